// How long the browser viewer takes to show a whole view sharp, cold: a
// fresh server with the bundled `default` texture, and each view at a place
// no request has touched (so neither the server's tile cache nor the
// viewer's holds any of it). Times run from setting the view to the canvas
// saying `data-complete="1"` at the level of detail that matches the screen
// (every visible tile of that level drawn), and are printed as
//
//   zoom-out 0.25 px/voxel complete in N ms
//
// lines (the goal is 2 s on two cores), with the same for 1 px/voxel and
// an oblique cut at 1 px/voxel. The zoom-out is asserted within a generous
// bound that only a broken viewer misses, SOLIDTEX_ZOOM_BOUND_MS (default 30000); the
// others are only printed. Then a zoom out of a whole view must show no
// background in its first frame (a coarser level scaled up instead).
// Screenshots go to ARTEFACTS.

import assert from "node:assert/strict";
import { mkdirSync } from "node:fs";
import { join } from "node:path";
import { ARTEFACTS, defaultReady, launch, startServer } from "./browser.mjs";

const BOUND = Number(process.env.SOLIDTEX_ZOOM_BOUND_MS || 30_000);

mkdirSync(ARTEFACTS, { recursive: true });
const server = await startServer([], { defaultTexture: true });
let browser = null;
const errors = [];
try {
  await defaultReady(server.base);

  browser = await launch({ width: 820, height: 540 });
  const page = await browser.context.newPage();
  // The viewer retries a 503 (an overloaded server) after Retry-After;
  // the browser logs it all the same. Counted, not failed.
  let overloaded = 0;
  page.on("console", (m) => {
    if (m.type() !== "error") return;
    if (/status of 503/.test(m.text())) overloaded++;
    else errors.push(m.text());
  });
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(`${server.base}/`);
  await page.waitForFunction(() => document.getElementById("plane").dataset.complete === "1", null, { timeout: 120_000 });
  const maxLod = await page.evaluate(() => window.solidtex.state.selected.max_lod);

  // Sets a view and times it in the page: the first tile drawn, and every
  // visible tile of the target level drawn.
  const measure = (view) => page.evaluate((view) => new Promise((done, fail) => {
    const c = document.getElementById("plane");
    const drawn0 = Number(c.dataset.drawn);
    const t0 = performance.now();
    let first = null, covered = null;
    window.solidtex.setView(view);
    const poll = () => {
      const now = performance.now() - t0;
      if (first == null && Number(c.dataset.drawn) > drawn0) first = now;
      if (covered == null && c.dataset.covered === "1") covered = now;
      if (c.dataset.complete === "1") {
        done({ ms: Math.round(now), first: Math.round(first ?? now), covered: Math.round(covered ?? now), lod: Number(c.dataset.lod), tiles: c.dataset.tiles });
      } else if (now > 120_000) {
        fail(new Error(`not complete after 120 s: ${JSON.stringify(c.dataset)}`));
      } else {
        requestAnimationFrame(poll);
      }
    };
    requestAnimationFrame(poll);
  }), view);

  // Every view somewhere new: far from the others and from the start view.
  const cases = [
    { what: "zoom-out 0.25 px/voxel", file: "viewer-zoom-0.25.png", view: { mode: "slice", axis: "z", scale: 0.25, position: 1_000_003, center: [-3_000_000, 5_000_000] }, lod: Math.min(2, maxLod), bound: true },
    { what: "zoom 1 px/voxel", file: "viewer-zoom-1.png", view: { mode: "slice", axis: "z", scale: 1, position: 2_000_005, center: [7_000_000, -2_000_000] }, lod: 0 },
    { what: "oblique cut 1 px/voxel", file: "viewer-zoom-cut-1.png", view: { mode: "cut", scale: 1, position: 3_000_007, center: [-6_000_000, -4_000_000] }, lod: 0 },
  ];
  const slow = [];
  for (const c of cases) {
    const r = await measure(c.view);
    const size = await page.evaluate(() => { const p = document.getElementById("plane"); return `${p.width}x${p.height}`; });
    console.log(`${c.what} complete in ${r.ms} ms (first tile ${r.first} ms, whole view coarse ${r.covered} ms, lod ${r.lod}, ${r.tiles} tiles, ${size} canvas)`);
    assert.equal(r.lod, c.lod, `${c.what}: level of detail`);
    await page.screenshot({ path: join(ARTEFACTS, c.file) });
    if (c.bound && r.ms > BOUND) slow.push(`${c.what}: ${r.ms} ms`);
  }
  // Zooming out of a whole view shows a coarser level scaled up in the
  // very first frame, not background: the viewer keeps a coarse backdrop
  // around the view once the view is whole.
  await page.evaluate(() => window.solidtex.setView({ mode: "slice", axis: "z", scale: 1, position: 4_000_009, center: [1_000_000, 9_000_000] }));
  await page.waitForFunction(() => {
    const s = window.solidtex.stats();
    return document.getElementById("plane").dataset.complete === "1" && s.inflight === 0 && s.queued === 0;
  }, null, { timeout: 120_000 });
  const background = await page.evaluate(() => new Promise((done) => {
    window.solidtex.setView({ scale: 0.5 });
    requestAnimationFrame(() => {
      const c = document.getElementById("plane");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
      let bg = 0;
      for (let i = 0; i < d.length; i += 4) if (d[i] === 13 && d[i + 1] === 14 && d[i + 2] === 16) bg++;
      done(bg / (d.length / 4));
    });
  }));
  console.log(`zoom-out to 0.5 px/voxel: ${(100 * background).toFixed(1)} % background in the first frame`);
  assert.ok(background < 0.01, `the first frame after a zoom-out is ${(100 * background).toFixed(1)} % background`);
  await page.screenshot({ path: join(ARTEFACTS, "viewer-zoom-out-first-frame.png") });

  if (overloaded) console.log(`(${overloaded} tile requests answered 503 and retried)`);
  assert.deepEqual(slow, [], `views slower than ${BOUND} ms`);
  assert.deepEqual(errors, [], "console errors");
  console.log("viewer zoom: ok");
} finally {
  if (browser) await browser.close();
  await server.stop();
}
