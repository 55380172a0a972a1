// Headless Chromium (playwright-core, Debian's chromium) on the try-on page:
//   node page.mjs URL SCREENSHOT.png
// picks a T-shirt and shorts, presses Dress, waits until the 3D view shows the returned GLB,
// saves a screenshot and prints a JSON summary. Any request leaving the server fails the run
// (the page must work offline), and so does any console error.
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { chromium } from "playwright-core";

const [url, screenshot] = process.argv.slice(2);
const origin = new URL(url).origin;
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const userDataDir = mkdtempSync(join(tmpdir(), "ulnef-chromium-"));
const garments = (process.env.PAGE_GARMENTS || "tshirt,shorts").split(",");
const untangle = process.env.PAGE_UNTANGLE !== "0";
const timeout = Number(process.env.PAGE_TIMEOUT_MS || 120000);

const summary = { outside: [], consoleErrors: [], status: "" };
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath,
  headless: true,
  viewport: { width: 1100, height: 800 },
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
});
try {
  const page = context.pages()[0] || await context.newPage();
  await page.route("**/*", (route) => {
    if (route.request().url().startsWith(origin)) return route.continue();
    summary.outside.push(route.request().url());
    return route.abort();
  });
  page.on("console", (m) => { if (m.type() === "error") summary.consoleErrors.push(m.text()); });
  page.on("pageerror", (e) => summary.consoleErrors.push(String(e)));
  await page.goto(url);
  await page.waitForSelector("body[data-ready=true]", { timeout: 30000 });
  for (const id of garments) await page.check(`input[name=garment][value=${id}]`);
  if (!untangle) await page.uncheck("#untangle");
  summary.layers = await page.$$eval("#layers li", (items) => items.map((li) => li.firstChild.textContent));
  await page.click("#dress");
  await page.waitForFunction(() => {
    const viewer = document.querySelector("model-viewer");
    return viewer.loaded && viewer.modelIsVisible || document.querySelector("#status.error");
  }, null, { timeout, polling: 250 });
  summary.status = await page.textContent("#status");
  summary.src = await page.$eval("model-viewer", (v) => v.src);
  summary.loaded = await page.$eval("model-viewer", (v) => v.loaded);
  await page.waitForTimeout(1500); // let the first frames and the shadow settle
  await page.screenshot({ path: screenshot });
} finally {
  await context.close();
  rmSync(userDataDir, { recursive: true, force: true });
}
process.stdout.write(JSON.stringify(summary));
