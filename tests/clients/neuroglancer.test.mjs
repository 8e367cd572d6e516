// The real Neuroglancer client (the static build shipped in the
// `neuroglancer` PyPI package, served on loopback by that package) opens
// `precomputed://http://127.0.0.1:PORT/v1/textures/ID/precomputed` in
// headless Chromium and renders the texture: the cross-section is not
// blank and no chunk request fails. The screenshot goes to ARTEFACTS.
//
//   PYTHON=venv/bin/python node neuroglancer.test.mjs

import assert from "node:assert/strict";
import { mkdirSync, writeFileSync } from "node:fs";
import { join } from "node:path";
import { spawn } from "node:child_process";
import { ARTEFACTS, HERE, launch, pngStats, readyTexture, startServer } from "./browser.mjs";

const PYTHON = process.env.PYTHON || "python3";

/// Starts the package's own viewer server with `state`; resolves to
/// { url, stop }.
function neuroglancer(state) {
  const proc = spawn(PYTHON, [join(HERE, "neuroglancer_viewer.py"), JSON.stringify(state)], {
    stdio: ["pipe", "pipe", "inherit"],
  });
  return new Promise((ok, fail) => {
    let out = "";
    proc.stdout.on("data", (d) => {
      out += d;
      const m = out.match(/(http:\/\/\S+)/);
      if (m) {
        ok({
          url: m[1],
          async stop() {
            proc.stdin.end();
            await new Promise((r) => proc.once("exit", r));
          },
        });
      }
    });
    proc.once("exit", (code) => fail(new Error(`neuroglancer exited (${code}): ${out}`)));
  });
}

mkdirSync(ARTEFACTS, { recursive: true });
const server = await startServer(["--chunk-size", "32"]);
let site = null;
let browser = null;
try {
  const tex = await readyTexture(server.base, join(HERE, "exemplar32.png"), "levels=3");
  const source = `precomputed://${server.base}/v1/textures/${tex.id}/precomputed`;
  // One cross-section at the coarsest scale (4 nm voxels shown 1:1), RGB
  // from the three channels.
  const viewerState = {
    dimensions: { x: [1e-9, "m"], y: [1e-9, "m"], z: [1e-9, "m"] },
    position: [0.5, 0.5, 40.5],
    crossSectionScale: 2 ** tex.max_lod,
    layout: "xy",
    showAxisLines: false,
    showScaleBar: false,
    layers: [{
      type: "image",
      name: "solidtex",
      source,
      channelDimensions: { "c^": [1, ""] },
      shader: "void main() { emitRGB(vec3(toNormalized(getDataValue(0)), toNormalized(getDataValue(1)), toNormalized(getDataValue(2)))); }",
    }],
    selectedLayer: { visible: false },
  };
  site = await neuroglancer(viewerState);
  browser = await launch({ width: 400, height: 300 });
  const page = await browser.context.newPage();
  const failed = [];
  const chunks = new Set(), pending = new Set();
  const isChunk = (url) => url.includes("/precomputed/") && !url.endsWith("/info");
  page.on("request", (r) => { if (isChunk(r.url())) pending.add(r.url()); });
  page.on("requestfailed", (r) => {
    pending.delete(r.url());
    failed.push(`${r.url()} ${r.failure()?.errorText}`);
  });
  page.on("response", (r) => {
    if (!r.url().includes("/precomputed/")) return;
    if (r.status() >= 400) failed.push(`${r.url()} ${r.status()}`);
    else if (isChunk(r.url())) chunks.add(r.url());
  });
  page.on("requestfinished", (r) => pending.delete(r.url()));
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(site.url);

  // Wait until the middle of the panel is drawn from chunks: textured, no
  // grey left (Neuroglancer leaves missing chunks grey). It asks for the
  // chunks nearest the centre first, then for the rest and for
  // neighbours to prefetch, which this test does not wait for.
  const t0 = Date.now();
  const centre = { x: 130, y: 110, w: 140, h: 110 };
  let shot, st;
  for (;;) {
    await page.waitForTimeout(1000);
    shot = await page.screenshot();
    st = await pngStats(browser.context, shot, centre);
    if (st.grey < 0.005 && st.std > 6) break;
    assert.ok(Date.now() - t0 < 180_000, `the panel is still blank: ${JSON.stringify(st)}`);
  }
  writeFileSync(join(ARTEFACTS, "neuroglancer.png"), shot);
  assert.deepEqual(failed, [], "failed requests");
  assert.ok(chunks.size > 0, "Neuroglancer fetched no chunk");
  assert.ok(st.mean > 30, `the panel looks dark: ${JSON.stringify(st)}`);
  assert.deepEqual(errors, [], "page errors");
  console.log(`neuroglancer: ok (${chunks.size} chunks in ${((Date.now() - t0) / 1000).toFixed(1)} s)`);
} finally {
  if (browser) await browser.close();
  if (site) await site.stop();
  await server.stop();
}
