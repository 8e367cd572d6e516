// The browser viewer in headless Chromium: an exemplar dropped on the page
// is uploaded and becomes ready, its slice is drawn and is not blank, the
// position slider changes it, the oblique cut and the 3D preview draw, and
// the console stays free of errors. Screenshots go to ARTEFACTS.

import assert from "node:assert/strict";
import { mkdirSync, readFileSync } from "node:fs";
import { join } from "node:path";
import { ARTEFACTS, HERE, launch, pngStats, startServer } from "./browser.mjs";

mkdirSync(ARTEFACTS, { recursive: true });
const server = await startServer();
let browser = null;
const errors = [];
try {
  browser = await launch({ width: 820, height: 540 });
  const page = await browser.context.newPage();
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(`${server.base}/`);
  await page.waitForSelector("#drop");
  assert.equal(await page.locator("#textures li").count(), 0, "a fresh server lists no texture");

  // Drop the exemplar on the drop zone, as a user would.
  const png = readFileSync(join(HERE, "exemplar32.png")).toString("base64");
  await page.evaluate((b64) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const dt = new DataTransfer();
    dt.items.add(new File([bytes], "exemplar32.png", { type: "image/png" }));
    document.getElementById("drop").dispatchEvent(new DragEvent("drop", { dataTransfer: dt, bubbles: true, cancelable: true }));
  }, png);
  await page.waitForSelector("#textures li[data-status]", { timeout: 10_000 });
  await page.screenshot({ path: join(ARTEFACTS, "viewer-upload.png") });
  await page.waitForSelector("#textures li[data-status=ready]", { timeout: 120_000 });
  await page.waitForFunction(() => /is ready|known already/.test(document.getElementById("status").textContent));

  // The ready texture is selected and its slice drawn.
  const drawn = () => page.evaluate(() => Number(document.getElementById("plane").dataset.drawn));
  const waitDrawn = (above) => page.waitForFunction(
    (n) => Number(document.getElementById("plane").dataset.drawn) > n, above, { timeout: 120_000 });
  const pixels = () => page.evaluate(() => {
    const c = document.getElementById("plane");
    return Array.from(c.getContext("2d").getImageData(0, 0, c.width, c.height).data);
  });
  const stats = (px) => {
    let s = 0, q = 0, n = 0;
    for (let i = 0; i < px.length; i += 4) for (let k = 0; k < 3; k++) { s += px[i + k]; q += px[i + k] ** 2; n++; }
    const m = s / n;
    return { mean: m, std: Math.sqrt(q / n - m * m) };
  };
  await waitDrawn(0);
  // Wait for the first refinement too, so the screenshot is sharp enough.
  await waitDrawn(1);
  const before = await pixels();
  const st = stats(before);
  assert.ok(st.std > 8, `slice looks blank: ${JSON.stringify(st)}`);
  await page.screenshot({ path: join(ARTEFACTS, "viewer-slice.png") });

  // Move the slider: a new slice is drawn and differs.
  const n0 = await drawn();
  await page.locator("#position").fill("41");
  await waitDrawn(n0);
  await page.waitForFunction(() => document.getElementById("hud").textContent.includes("z = 41"));
  const after = await pixels();
  let changed = 0;
  for (let i = 0; i < before.length; i += 4) if (before[i] !== after[i] || before[i + 1] !== after[i + 1]) changed++;
  assert.ok(changed > before.length / 4 / 4, `the slice hardly changed (${changed} pixels)`);
  await page.screenshot({ path: join(ARTEFACTS, "viewer-slice-moved.png") });

  // Keyboard: the y axis, then the oblique cut.
  await page.locator("#plane").focus();
  const n1 = await drawn();
  await page.keyboard.press("y");
  await waitDrawn(n1);
  assert.equal(await page.locator("#axis").inputValue(), "y");
  const n2 = await drawn();
  await page.keyboard.press("c");
  await waitDrawn(n2);
  assert.ok(stats(await pixels()).std > 8, "cut looks blank");
  await page.screenshot({ path: join(ARTEFACTS, "viewer-cut.png") });

  // The 3D preview: a carved sphere, then a deeper cut redraws it.
  await page.keyboard.press("v");
  await page.waitForFunction(() => Number(document.getElementById("solid").dataset.drawn) > 0, null, { timeout: 120_000 });
  const box = await page.locator("#solid").boundingBox();
  const shot1 = await page.screenshot({ clip: box });
  const s1 = await pngStats(browser.context, shot1);
  assert.ok(s1.std > 8, `3D preview looks blank: ${JSON.stringify(s1)}`);
  await page.screenshot({ path: join(ARTEFACTS, "viewer-3d.png") });
  await page.locator("#carve").fill("-40");
  const shot2 = await page.screenshot({ clip: box });
  assert.notDeepEqual(shot1, shot2, "the cut did not change the 3D preview");
  // Orbit with the mouse.
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 40, { steps: 5 });
  await page.mouse.up();
  await page.screenshot({ path: join(ARTEFACTS, "viewer-3d-orbit.png") });

  assert.deepEqual(errors, [], "console errors");
  console.log("viewer: ok");
} finally {
  if (browser) await browser.close();
  await server.stop();
}
