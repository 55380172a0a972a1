// Headless Chromium (playwright-core, Debian's chromium) on the try-on page:
//   node page.mjs URL SCREENSHOT.png
// waits for the default outfit (its timings: summary.first), records the sliders' and girth inputs'
// ranges for a man and a woman and what a refused request (a hip girth no woman of her height and
// weight has) leaves on screen, then picks a T-shirt and shorts and a hip girth (the middle of its
// range), then for each GLB encoding of PAGE_COMPRESSIONS (default "none") picks it, presses Dress, waits until the 3D view has loaded the returned GLB, saves a screenshot
// (SCREENSHOT-<encoding>.png) and records the GLB it fetched; prints a JSON summary. Any request
// leaving the server fails the run (the page must work offline), and so does any console error.
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
const compressions = (process.env.PAGE_COMPRESSIONS || "none").split(",");
const timeout = Number(process.env.PAGE_TIMEOUT_MS || 120000);

const summary = { outside: [], consoleErrors: [], runs: [] };
const glbs = {}; // GLB path and query -> {bytes, extensionsRequired}

function glbSummary(body) {
  if (body.length < 20 || body.toString("latin1", 0, 4) !== "glTF") return { bytes: body.length };
  const doc = JSON.parse(body.toString("utf8", 20, 20 + body.readUInt32LE(12)));
  return { bytes: body.length, extensionsRequired: doc.extensionsRequired || [] };
}

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
  page.on("response", async (response) => {
    const { pathname, search } = new URL(response.url());
    if (pathname.endsWith(".glb") && response.ok()) glbs[pathname + search] = glbSummary(await response.body());
  });
  await page.goto(url);
  await page.waitForSelector("body[data-ready=true]", { timeout: 30000 });
  // The default outfit, shown without a click: where its time on screen goes.
  await page.waitForSelector("body[data-first=done]", { timeout });
  summary.first = await page.evaluate(() => ({
    layers: [...document.querySelectorAll("#layers li")].map((li) => li.firstChild.textContent),
    shown: document.body.dataset.shown || null,
    status: document.querySelector("#status").textContent,
    statusLog: window.statusLog,
    measured: JSON.parse(document.body.dataset.measured || "null"),
    measuredText: document.querySelector("#measured").textContent,
    timings: window.pageTimings,
    resources: performance.getEntriesByType("resource").map((r) => ({
      name: new URL(r.name).pathname, start: Math.round(r.startTime), end: Math.round(r.responseEnd),
    })),
  }));
  // The sliders and girth inputs follow the ranges, and a refusal leaves an empty view and its message.
  const sliders = () => page.evaluate(() => Object.fromEntries(
    ["height", "weight", "chest", "waist", "hip"].map((id) => {
      const s = document.getElementById(id);
      return [id, [Number(s.min), Number(s.max), s.value === "" ? null : Number(s.value)]];
    })));
  summary.ranges = { male: await sliders() };
  await page.$eval("#gender", (s) => { s.value = "1"; s.dispatchEvent(new Event("change")); });
  await page.waitForSelector("body[data-ranges^='1 ']", { timeout: 30000 });
  summary.ranges.female = await sliders();
  await page.fill("#hip", "300"); // beyond the input's max: sent anyway, refused by the service
  await page.click("#dress");
  await page.waitForSelector("#status.error", { timeout });
  summary.refusal = await page.evaluate(() => ({
    status: document.querySelector("#status").textContent,
    src: document.querySelector("model-viewer").getAttribute("src"),
    shown: document.body.dataset.shown || null,
  }));
  await page.$eval("#height", (s) => { s.value = "178"; });
  await page.$eval("#weight", (s) => { s.value = "75"; });
  await page.$eval("#gender", (s) => { s.value = "0"; s.dispatchEvent(new Event("change")); });
  await page.waitForSelector("body[data-ranges^='0 ']", { timeout: 30000 });
  summary.hip = await page.$eval("#hip", (s) => {
    s.value = ((Number(s.min) + Number(s.max)) / 2).toFixed(0);
    return Number(s.value);
  });
  for (const box of await page.$$("input[name=garment]:checked")) await box.uncheck();
  for (const id of garments) await page.check(`input[name=garment][value=${id}]`);
  if (!untangle) await page.uncheck("#untangle");
  summary.layers = await page.$$eval("#layers li", (items) => items.map((li) => li.firstChild.textContent));
  // Dress with the controls as set; the viewer's load (or error) event, the status and a screenshot.
  async function dressAndShoot(label) {
    // The viewer's next load or error event (its `loaded` stays true from the last model until then).
    await page.evaluate(() => {
      const viewer = document.querySelector("model-viewer");
      window.viewerEvent = null;
      viewer.addEventListener("load", () => { window.viewerEvent = "load"; }, { once: true });
      viewer.addEventListener("error", (e) => {
        window.viewerEvent = `error: ${e.detail?.sourceError || e.detail?.type}`;
      }, { once: true });
    });
    await page.click("#dress");
    await page.waitForFunction(() => window.viewerEvent || document.querySelector("#status.error"),
                               null, { timeout, polling: 250 });
    await page.waitForFunction(() => window.viewerEvent !== "load"
                                     || document.querySelector("model-viewer").modelIsVisible,
                               null, { timeout, polling: 250 });
    const event = await page.evaluate(() => window.viewerEvent);
    const run = { event, status: await page.textContent("#status") };
    run.src = await page.$eval("model-viewer", (v) => v.src);
    run.loaded = await page.$eval("model-viewer", (v) => v.loaded);
    await page.waitForTimeout(1500); // let the first frames and the shadow settle
    run.screenshot = screenshot.replace(/\.png$/, "") + `-${label}.png`;
    await page.screenshot({ path: run.screenshot });
    const { pathname, search } = new URL(run.src, origin);
    run.glb = glbs[pathname + search] || null;
    run.measured = await page.evaluate(() => JSON.parse(document.body.dataset.measured || "null"));
    return run;
  }
  for (const compression of compressions) {
    await page.selectOption("#compression", compression);
    summary.runs.push({ compression, ...(await dressAndShoot(compression)) });
  }
  // The T-shirt in S with the tension map (the plain encoding, whatever the encoding picked).
  await page.selectOption("select[name=size-tshirt]", "S");
  await page.check("#tension");
  summary.tension = await dressAndShoot("tension");
} finally {
  await context.close();
  rmSync(userDataDir, { recursive: true, force: true });
}
process.stdout.write(JSON.stringify(summary));
