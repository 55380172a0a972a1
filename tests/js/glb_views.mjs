// Render GLB files with the page's own viewer (model-viewer, vendored) in headless Chromium:
//   node glb_views.mjs OUT_DIR ORBIT a.glb b.glb ...   ->  OUT_DIR/a.png, OUT_DIR/b.png
// ORBIT is model-viewer's camera-orbit, e.g. "20deg 80deg auto". No server and no network: the
// viewer script is injected from service/server/static/vendor and each GLB is a data URL.
import { readFileSync } from "node:fs";
import { basename, join } from "node:path";
import { chromium } from "playwright-core";

const [outDir, orbit, ...files] = process.argv.slice(2);
const viewer = new URL("../../service/server/static/vendor/model-viewer.min.js", import.meta.url).pathname;
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
});
try {
  const page = await browser.newPage({ viewport: { width: 600, height: 800 } });
  await page.route("**/*", (route) => (route.request().url().startsWith("data:") ? route.continue() : route.abort()));
  for (const file of files) {
    const src = `data:model/gltf-binary;base64,${readFileSync(file).toString("base64")}`;
    await page.setContent(`<body style="margin:0;background:#fff"><model-viewer id="v" camera-orbit="${orbit}"
      environment-image="neutral" style="width:600px;height:800px"></model-viewer></body>`);
    await page.addScriptTag({ path: viewer, type: "module" });
    await page.evaluate((s) => { document.getElementById("v").src = s; }, src);
    await page.waitForFunction(() => document.getElementById("v").loaded, null, { timeout: 120000 });
    await page.waitForTimeout(1000);
    await page.screenshot({ path: join(outDir, basename(file).replace(/\.glb$/, ".png")) });
  }
} finally {
  await browser.close();
}
