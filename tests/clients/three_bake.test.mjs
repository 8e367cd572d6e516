// Baked meshes as an engine shows them: three.js's own GLTFLoader, in
// headless Chromium, loads GLBs the bake route made from the shipped torus
// and the bundled marble (three_bake.html draws them):
//  - the whole torus: every triangle arrives, with one sRGB base-colour
//    texture of the size the file declares;
//  - it is drawn textured: its pixels take the texture's colour (their mean
//    chromaticity is the texture's, where the same mesh drawn untextured is
//    grey) and its detail (the step between neighbouring pixels is well
//    above the untextured mesh's, which has shading alone);
//  - the torus cut through its ring into two pieces, pulled apart: two
//    meshes, capped, both textured; the caps (each piece's coplanar
//    triangles, marked in a second, unshaded draw) are drawn in the
//    marble's colour with its veins, where untextured they are flat;
//  - the same cut of a region texture with a shell (Zhang et al.'s bark:
//    marble for 10 voxels below the surface, wood deeper, the fixture's
//    wood5): the surface is drawn as the marble's, the caps apart from
//    the marble's caps (wood ringed with marble).
// The screenshots (three-bake.png, three-cut.png, three-shell.png) go to
// ARTEFACTS; README's and docs/meshes.md's pictures are them.
//
//   node three_bake.test.mjs

import assert from "node:assert/strict";
import { copyFileSync, mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { ARTEFACTS, HERE, ROOT, defaultReady, launch, readyTexture, routeThree, serveStatic, startServer } from "./browser.mjs";

const TORUS = readFileSync(join(ROOT, "tests", "fixtures", "meshes", "torus.obj"));
const TORUS_TRIANGLES = 2304;

/// The sizes of the PNG images a GLB embeds, read from the file itself.
function embeddedImageSizes(glb) {
  const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
  assert.equal(view.getUint32(0, true), 0x46546c67, "glTF magic");
  const jsonLength = view.getUint32(12, true);
  const json = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLength)));
  const bin = 20 + jsonLength + 8;
  return (json.images || []).map((image) => {
    const bv = json.bufferViews[image.bufferView];
    const png = glb.subarray(bin + (bv.byteOffset || 0));
    // The IHDR chunk follows the 8-byte signature and its own 8-byte head.
    const ihdr = new DataView(png.buffer, png.byteOffset + 16, 8);
    return { width: ihdr.getUint32(0), height: ihdr.getUint32(4) };
  });
}

/// Chromaticity: a colour's share of each channel.
const chroma = (rgb) => rgb.map((c) => c / (rgb[0] + rgb[1] + rgb[2]));
const apart = (a, b) => Math.max(...a.map((v, i) => Math.abs(v - b[i])));

mkdirSync(ARTEFACTS, { recursive: true });
const site = mkdtempSync(join(tmpdir(), "solidtex-three-"));
const server = await startServer([], { defaultTexture: true });
let statics, browser;
try {
  await defaultReady(server.base);
  const wood = await readyTexture(server.base, join(ROOT, "tests", "fixtures", "exemplars", "wood_wood5.png"), "");
  const made = await fetch(`${server.base}/v1/textures`, {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ outer: "default", inner: wood.id, band: 4, region: { shape: "shell", thickness: 10 } }),
  });
  assert.equal(made.status, 201, await made.clone().text());
  const shell = (await made.json()).id;
  const bake = async (query, id = "default") => {
    const res = await fetch(`${server.base}/v1/textures/${id}/bake?${query}`, { method: "POST", body: TORUS });
    assert.equal(res.status, 200, `${query}: ${await res.clone().text()}`);
    return new Uint8Array(await res.arrayBuffer());
  };
  const files = {
    torus: await bake("resolution=256"),
    cut: await bake("resolution=256&cut=1,0,0,0&spread=0.12"),
    shell: await bake("resolution=256&cut=1,0,0,0&spread=0.12", shell),
  };
  for (const [name, b] of Object.entries(files)) writeFileSync(join(site, `${name}.glb`), b);
  copyFileSync(join(HERE, "three_bake.html"), join(site, "index.html"));
  statics = await serveStatic(site);
  browser = await launch({ width: 800, height: 500 });
  await routeThree(browser.context);
  const errors = [];
  const draw = async (query, shot) => {
    const page = await browser.context.newPage();
    page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
    page.on("pageerror", (e) => errors.push(String(e)));
    await page.goto(`${statics.base}/index.html?${query}`);
    await page.waitForSelector("body[data-ready=true]", { timeout: 120_000 });
    const result = await page.evaluate(() => window.result);
    assert.equal(result.error, undefined, `${query}: ${result.error}`);
    if (shot) await page.screenshot({ path: join(ARTEFACTS, shot) });
    await page.close();
    return result;
  };

  const textured = await draw("glb=torus.glb", "three-bake.png");
  const plain = await draw("glb=torus.glb&plain");
  console.log("torus:", JSON.stringify(textured));
  console.log("torus untextured:", JSON.stringify(plain));
  assert.equal(textured.meshes, 1);
  assert.equal(textured.triangles, TORUS_TRIANGLES);
  assert.deepEqual(textured.textures.map(({ width, height }) => ({ width, height })), embeddedImageSizes(files.torus));
  assert.ok(textured.textures.every((t) => t.srgb), "base colour read as sRGB");
  assert.ok(textured.coverage > 0.1 && textured.coverage < 0.9, `coverage ${textured.coverage}`);
  // Coloured like the texture, where the untextured mesh is grey.
  const tex = chroma(textured.textureMean);
  const off = apart(chroma(textured.objectMean), tex);
  const plainOff = apart(chroma(plain.objectMean), tex);
  assert.ok(off < 0.02 && off < plainOff / 2, `drawn ${off.toFixed(4)} from the texture's colour, untextured ${plainOff.toFixed(4)}`);
  // Detail beyond shading.
  assert.ok(textured.objectStep > 1.3 * plain.objectStep, `pixel steps ${textured.objectStep} against ${plain.objectStep} untextured`);

  const cut = await draw("glb=cut.glb&dir=0.8,0.9,1.0", "three-cut.png");
  console.log("cut:", JSON.stringify(cut));
  assert.equal(cut.meshes, 2, "two pieces");
  assert.ok(cut.triangles > TORUS_TRIANGLES, `capped: ${cut.triangles} triangles`);
  assert.equal(cut.textures.length, 2, "both pieces textured");
  assert.ok(apart(chroma(cut.objectMean), chroma(cut.textureMean)) < 0.02, "the pieces drawn in the texture's colour");
  // The caps: found as each piece's coplanar triangles, a real share of the
  // picture, drawn in the marble's colour and with its veins, where the
  // same caps untextured are flat.
  const cutPlain = await draw("glb=cut.glb&dir=0.8,0.9,1.0&plain");
  console.log("cut untextured:", JSON.stringify(cutPlain));
  assert.equal(textured.capTriangles, 0, "the whole torus has no cap");
  assert.ok(cut.capTriangles > 0 && cut.capTriangles === cutPlain.capTriangles, `cap triangles ${cut.capTriangles}`);
  assert.ok(cut.capCoverage > 0.005, `caps cover ${cut.capCoverage} of the picture`);
  const capOff = apart(chroma(cut.capMean), chroma(cut.textureMean));
  assert.ok(capOff < 0.03, `caps drawn ${capOff.toFixed(4)} from the texture's colour`);
  assert.ok(cut.capStep > 2 * cutPlain.capStep, `cap pixel steps ${cut.capStep} against ${cutPlain.capStep} untextured`);
  const bark = await draw("glb=shell.glb&dir=0.8,0.9,1.0", "three-shell.png");
  console.log("shell:", JSON.stringify(bark));
  assert.equal(bark.meshes, 2, "two pieces");
  assert.equal(bark.triangles, cut.triangles, "the same pieces");
  assert.equal(bark.textures.length, 2, "both pieces textured");
  assert.equal(bark.capTriangles, cut.capTriangles, "the same caps");
  // The surface is the marble's either way; the caps show the wood within.
  const surfaceOff = apart(chroma(bark.surfaceMean), chroma(cut.surfaceMean));
  const capsOff = apart(chroma(bark.capMean), chroma(cut.capMean));
  assert.ok(surfaceOff < 0.002, `the shell's surface ${surfaceOff.toFixed(4)} from the marble's`);
  assert.ok(capsOff > 0.008 && capsOff > 4 * surfaceOff, `the shell's caps ${capsOff.toFixed(4)} from the marble's caps`);
  assert.deepEqual(errors, [], "console errors");
  console.log("three.js: GLTFLoader draws the baked torus and its cut pieces textured");
} finally {
  if (browser) await browser.close();
  if (statics) await statics.stop();
  await server.stop();
  rmSync(site, { recursive: true, force: true });
}
