// The viewer's mesh view in headless Chromium: the torus shipped with the
// repository (the viewer writes tests/fixtures/meshes/torus.obj byte for
// byte) is baked through the bake route and drawn textured and lit; the
// cutting plane's cap shows the solid on that plane: sampled cap pixels
// equal the cut route's trilinear sample at the same point of texture
// space, placed the way the bake route documents (the model's bounding box,
// longest side = resolution voxels, lowest corner at the origin). Moving
// the plane (slider, then Shift-drag) changes the cap and the image. The
// view is left as ARTEFACTS/viewer-mesh.png (README's screenshot).
//
//   node viewer_mesh.test.mjs

import assert from "node:assert/strict";
import { mkdirSync, readFileSync } from "node:fs";
import { join } from "node:path";
import { ARTEFACTS, ROOT, defaultReady, launch, pngStats, startServer } from "./browser.mjs";

const TORUS = readFileSync(join(ROOT, "tests", "fixtures", "meshes", "torus.obj"), "utf8");
mkdirSync(ARTEFACTS, { recursive: true });

// The fixture's bounding box, read here rather than from the viewer.
const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
for (const line of TORUS.split("\n")) {
  if (!line.startsWith("v ")) continue;
  line.slice(2).split(" ").map(Number).forEach((x, a) => {
    lo[a] = Math.min(lo[a], x);
    hi[a] = Math.max(hi[a], x);
  });
}
const longest = Math.max(...hi.map((x, a) => x - lo[a]));

const server = await startServer([], { defaultTexture: true });
let browser = null;
const errors = [];
try {
  await defaultReady(server.base);
  browser = await launch({ width: 1200, height: 760 });
  const page = await browser.context.newPage();
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(`${server.base}/`);
  await page.waitForFunction(() => window.solidtex.state.selected && window.solidtex.state.selected.status === "ready", null, { timeout: 60_000 });
  assert.equal(await page.evaluate(() => window.solidtex.mesh.torusObj()), TORUS, "the viewer's torus is not the shipped one");

  await page.locator("#plane").focus();
  await page.keyboard.press("m");
  const capped = (prev) => page.waitForFunction((p) => {
    const c = document.getElementById("mesh");
    const plane = window.solidtex.mesh.capPlane();
    return c.dataset.baked === "1" && c.dataset.capped === "1" && c.dataset.cap !== p && plane && c.dataset.cap === plane.url;
  }, prev, { timeout: 240_000 });
  await capped(null);
  const model = await page.evaluate(() => window.solidtex.mesh.model());
  assert.equal(model.triangles, 2304);
  assert.deepEqual(model.lo.map((x) => +x.toFixed(5)), lo.map((x) => +x.toFixed(5)));

  const box = await page.locator("#mesh").boundingBox();
  const shot = async () => page.screenshot({ clip: box });
  const first = await shot();
  const st = await pngStats(browser.context, first);
  assert.ok(st.std > 12, `the mesh view looks blank: ${JSON.stringify(st)}`);

  // Cap pixels against the cut route at the same points of texture space.
  const checkCap = async () => {
    const r = await page.evaluate(async ({ lo, longest }) => {
      const m = window.solidtex.mesh;
      const p = m.capPlane(), cap = m.capPixels();
      const scale = m.model().resolution / longest;
      const step = (2 * p.half) / p.N;
      const out = { checked: 0, off: [], onPlane: 0, inside: 0 };
      const id = window.solidtex.state.selected.id;
      // A grid of cap pixels, the ones inside the solid only (where the
      // cap shows): those whose voxel the cut route gives.
      for (let gy = 1; gy < 12; gy++) {
        for (let gx = 1; gx < 12; gx++) {
          const a = Math.floor((gx * p.N) / 12), b = Math.floor((gy * p.N) / 12);
          const s = -p.half + (a + 0.5) * step, t = -p.half + (b + 0.5) * step;
          const q = p.c.map((x, k) => x + s * p.U[k] + t * p.V[k]);
          // On the clip plane.
          if (Math.abs(p.n[0] * q[0] + p.n[1] * q[1] + p.n[2] * q[2] - p.d) < 1e-6) out.onPlane++;
          // Inside the torus (radii 1 and 0.35 about the z axis)?
          const ring = Math.hypot(q[0], q[1]) - 1;
          if (Math.hypot(ring, q[2]) > 0.33) continue;
          out.inside++;
          const v = q.map((x, k) => ((x - lo[k]) * scale).toFixed(6)).join(",");
          const res = await fetch(`/v1/textures/${id}/cut.png?origin=${v}&u=1,0,0&v=0,1,0&w=1&h=1&lod=0&filter=trilinear`);
          const bmp = await createImageBitmap(await res.blob());
          const c = new OffscreenCanvas(1, 1).getContext("2d");
          c.drawImage(bmp, 0, 0);
          const want = c.getImageData(0, 0, 1, 1).data;
          const i = 4 * (b * cap.w + a);
          const got = cap.data.slice(i, i + 3);
          out.checked++;
          if ([0, 1, 2].some((k) => Math.abs(got[k] - want[k]) > 2)) out.off.push({ a, b, got, want: Array.from(want.slice(0, 3)) });
        }
      }
      return { ...out, url: cap.url, data: cap.data };
    }, { lo, longest });
    assert.equal(r.onPlane, 121, "cap points off the clipping plane");
    assert.ok(r.checked >= 8, `too few cap pixels inside the solid: ${r.checked}`);
    assert.deepEqual(r.off, [], "cap pixels that are not the solid's voxel there");
    return r;
  };
  const c1 = await checkCap();
  console.log(`cap: ${c1.checked} pixels inside the solid equal the cut route's samples`);

  // The plane slider: a new cap, a new picture.
  await page.locator("#mesh-cut").fill("-20");
  await capped(c1.url);
  const c2 = await checkCap();
  let changed = 0;
  for (let i = 0; i < c1.data.length; i += 4) if (c1.data[i] !== c2.data[i]) changed++;
  assert.ok(changed > c1.data.length / 4 / 4, `the cap hardly changed: ${changed} pixels`);
  const second = await shot();
  assert.notDeepEqual(first, second, "moving the plane did not change the view");

  // Shift-drag moves the plane as well.
  const before = await page.evaluate(() => window.solidtex.state.meshCut);
  await page.keyboard.down("Shift");
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2 - 60, { steps: 4 });
  await page.mouse.up();
  await page.keyboard.up("Shift");
  const after = await page.evaluate(() => window.solidtex.state.meshCut);
  assert.ok(after > before + 0.05, `Shift-drag did not move the plane: ${before} → ${after}`);
  await capped(c2.url);
  await checkCap();

  // The picture for README: the plane through the ring, seen from above.
  const last = await page.evaluate(() => document.getElementById("mesh").dataset.cap);
  await page.locator("#mesh-cut").fill("8");
  await page.locator("#yaw").fill("20");
  await page.locator("#pitch").fill("10");
  await capped(last);
  await page.locator("#mesh").focus();
  await page.screenshot({ path: join(ARTEFACTS, "viewer-mesh.png") });

  assert.deepEqual(errors, [], "console errors");
  console.log("viewer mesh: ok");
} finally {
  if (browser) await browser.close();
  await server.stop();
}
