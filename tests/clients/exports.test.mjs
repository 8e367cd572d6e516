// KTX2 exports read by tools that are not ours: ktx-parse (npm) parses the
// container and its level 0 holds the voxels `region.raw` gives; three.js's
// KTX2Loader in headless Chromium loads it as a Data3DTexture, and the
// shader example (docs/shader-example) draws it:
//  - nearest sampling shows the stored texels (within 1 of sRGB decoding
//    and encoding back);
//  - a 2×2 tiling of one period, sampled trilinearly with repeat wrapping,
//    has no seam: the luminance step across the period border lies within
//    the steps inside the tile, where a block of the aperiodic texture has
//    a step across its border larger than any inside;
//  - the carved object renders (screenshot in ARTEFACTS).
//
//   node exports.test.mjs

import assert from "node:assert/strict";
import { copyFileSync, mkdirSync, mkdtempSync, rmSync, writeFileSync } from "node:fs";
import { createRequire } from "node:module";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { ARTEFACTS, HERE, ROOT, launch, pngStats, readyTexture, routeThree, serveStatic, startServer } from "./browser.mjs";

const NODE = process.env.CLIENTS_NODE_DIR || join(ROOT, "target", "clients", "node");
const require = createRequire(join(NODE, "package.json"));
const { read } = await import(require.resolve("ktx-parse"));

const PERIOD = 32;

async function bytes(url) {
  const res = await fetch(url);
  if (!res.ok) throw new Error(`${url}: ${res.status} ${await res.text()}`);
  return new Uint8Array(await res.arrayBuffer());
}

/// Rec. 709 luminance of an RGBA or RGB pixel.
const luma = (p, i) => 0.2126 * p[i] + 0.7152 * p[i + 1] + 0.0722 * p[i + 2];

/// The seam measure of `solidtex_core::eval::tiling_seam`, on an image
/// that shows a tile `tile` pixels wide twice across: the mean luminance
/// step between neighbouring columns (rows) across the tile border,
/// against those steps everywhere else.
function seams({ width, height, rgba }, tile) {
  const at = (x, y) => luma(rgba, (y * width + x) * 4);
  const column = (x) => {
    let s = 0;
    for (let y = 0; y < height; y++) s += Math.abs(at(x + 1, y) - at(x, y));
    return s / height;
  };
  const row = (y) => {
    let s = 0;
    for (let x = 0; x < width; x++) s += Math.abs(at(x, y + 1) - at(x, y));
    return s / width;
  };
  const border = [column(tile - 1), row(tile - 1)];
  const inside = [];
  for (let x = 0; x < width - 1; x++) if (x !== tile - 1) inside.push(column(x));
  for (let y = 0; y < height - 1; y++) if (y !== tile - 1) inside.push(row(y));
  inside.sort((a, b) => a - b);
  const worst = Math.max(...border);
  const rank = inside.filter((s) => s < worst).length / inside.length;
  return { border, inside, median: inside[inside.length >> 1], max: inside[inside.length - 1], rank };
}

mkdirSync(ARTEFACTS, { recursive: true });
const server = await startServer();
const site = mkdtempSync(join(tmpdir(), "solidtex-shader-"));
let statics = null;
let browser = null;
const errors = [];
try {
  const exemplar = join(HERE, "exemplar32.png");
  const periodic = await readyTexture(server.base, exemplar, `levels=3&period=${PERIOD}`);
  const aperiodic = await readyTexture(server.base, exemplar, "levels=3");
  const url = (t, q) => `${server.base}/v1/textures/${t.id}/${q}`;

  // ktx-parse reads the container; level 0 is the region's voxels, RGBA.
  const files = {
    periodic: await bytes(url(periodic, "export?format=ktx2")),
    aperiodic: await bytes(url(aperiodic, `export?format=ktx2&x=0&y=0&z=0&w=${PERIOD}&h=${PERIOD}&d=${PERIOD}`)),
    linear: await bytes(url(periodic, "export?format=ktx2&colour=linear&mips=levels")),
  };
  const c = read(files.periodic);
  assert.equal(c.vkFormat, 43, "VK_FORMAT_R8G8B8A8_SRGB");
  assert.deepEqual([c.pixelWidth, c.pixelHeight, c.pixelDepth, c.layerCount, c.faceCount], [PERIOD, PERIOD, PERIOD, 0, 1]);
  assert.equal(c.levels.length, Math.log2(PERIOD) + 1, "a full mip chain");
  assert.equal(c.supercompressionScheme, 0);
  assert.equal(c.dataFormatDescriptor[0].transferFunction, 2, "sRGB transfer");
  assert.equal(c.keyValue.KTXorientation, "rdi");
  const text = (v) => (typeof v === "string" ? v : new TextDecoder().decode(v)).replace(/\0$/, "");
  const description = JSON.parse(text(c.keyValue.solidtex));
  assert.equal(description.tiles, true);
  c.levels.forEach((level, i) => {
    const side = PERIOD >> i;
    assert.equal(level.levelData.byteLength, side * side * side * 4, `level ${i}`);
  });
  const raw = await bytes(url(periodic, `region.raw?x=0&y=0&z=0&w=${PERIOD}&h=${PERIOD}&d=${PERIOD}`));
  const level0 = c.levels[0].levelData;
  for (let v = 0; v < raw.length / 3; v++) {
    for (let ch = 0; ch < 3; ch++) assert.equal(level0[v * 4 + ch], raw[v * 3 + ch], `voxel ${v}`);
    assert.equal(level0[v * 4 + 3], 255);
  }
  const lin = read(files.linear);
  assert.equal(lin.vkFormat, 37, "VK_FORMAT_R8G8B8A8_UNORM");
  assert.deepEqual(lin.levels[0].levelData, level0, "the same bytes, marked linear");

  // The shader example, with three.js from node_modules in place of the
  // CDN its import map names, and the exports beside it.
  copyFileSync(join(ROOT, "docs", "shader-example", "index.html"), join(site, "index.html"));
  for (const [name, b] of Object.entries(files)) writeFileSync(join(site, `${name}.ktx2`), b);
  statics = await serveStatic(site);
  browser = await launch({ width: 900, height: 540 });
  await routeThree(browser.context);
  const open = async (query) => {
    const page = await browser.context.newPage();
    page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
    page.on("pageerror", (e) => errors.push(String(e)));
    await page.goto(`${statics.base}/index.html?${query}`);
    await page.waitForSelector("body[data-ready=true]", { timeout: 60_000 });
    return page;
  };

  // Nearest sampling shows the stored texels: slice z = 5, tiled 2×2.
  {
    const page = await open("ktx2=periodic.ktx2&view=plane&filter=nearest&zoom=1&slice=5");
    const info = await page.evaluate(() => ({ size: window.solidtex.size, levels: window.solidtex.levels, cs: window.solidtex.colorSpace }));
    assert.deepEqual(info.size, [PERIOD, PERIOD, PERIOD]);
    assert.equal(info.cs, "srgb");
    const px = await page.evaluate(() => window.solidtex.pixels());
    assert.deepEqual([px.width, px.height], [2 * PERIOD, 2 * PERIOD]);
    let worst = 0;
    for (let y = 0; y < px.height; y++) {
      for (let x = 0; x < px.width; x++) {
        const v = ((5 * PERIOD + (y % PERIOD)) * PERIOD + (x % PERIOD)) * 3;
        for (let ch = 0; ch < 3; ch++) worst = Math.max(worst, Math.abs(px.rgba[(y * px.width + x) * 4 + ch] - raw[v + ch]));
      }
    }
    assert.ok(worst <= 1, `rendered texels differ from the voxels by up to ${worst}`);
    await page.close();
  }

  // Seams of the trilinear 2×2 tiling, periodic against aperiodic, over a
  // few slices. At zoom 2 every other column step is a whole half texel
  // difference, the border's kind, so the border of one slice can top the
  // few dozen of its kind inside by chance: the periodic tiling's border
  // steps are held against the steps inside all the slices together. A
  // block of the aperiodic texture shows its seam in every slice alone.
  const report = {};
  const pooled = { border: [], inside: [] };
  for (const name of ["periodic", "aperiodic"]) {
    report[name] = [];
    for (const slice of [0, 11, 31]) {
      const page = await open(`ktx2=${name}.ktx2&view=plane&zoom=2&slice=${slice}`);
      const px = await page.evaluate(() => window.solidtex.pixels());
      const s = seams(px, 2 * PERIOD);
      report[name].push({ border: s.border, median: s.median, max: s.max, rank: s.rank });
      console.log(`${name} slice ${slice}: border ${s.border.map((b) => b.toFixed(2)).join(" / ")}, inside median ${s.median.toFixed(2)}, max ${s.max.toFixed(2)}, rank ${s.rank.toFixed(3)}`);
      if (name === "periodic") {
        pooled.border.push(...s.border);
        pooled.inside.push(...s.inside);
      } else {
        assert.equal(s.rank, 1, `the aperiodic block shows no seam: ${JSON.stringify(report[name].at(-1))}`);
      }
      if (slice === 11) await page.screenshot({ path: join(ARTEFACTS, `shader-${name}-tiling.png`) });
      await page.close();
    }
  }
  const insideMax = Math.max(...pooled.inside);
  const worstBorder = Math.max(...pooled.border);
  console.log(`periodic, all slices: largest border step ${worstBorder.toFixed(2)}, largest inside ${insideMax.toFixed(2)}`);
  assert.ok(worstBorder <= insideMax, `a seam in the periodic tiling: ${JSON.stringify(report.periodic)}`);
  writeFileSync(join(ARTEFACTS, "shader-seams.json"), JSON.stringify(report, null, 1));

  // The carved object.
  {
    const page = await open("ktx2=periodic.ktx2&still");
    const shot = await page.screenshot({ path: join(ARTEFACTS, "shader-example.png") });
    const stats = await pngStats(browser.context, shot);
    assert.ok(stats.std > 8, `the object looks blank: ${JSON.stringify(stats)}`);
    await page.close();
  }
  assert.deepEqual(errors, [], "console errors");
  console.log("exports: ktx-parse and three.js read the KTX2 exports; no seam in the periodic tiling");
} finally {
  if (browser) await browser.close();
  if (statics) await statics.stop();
  await server.stop();
  rmSync(site, { recursive: true, force: true });
}
