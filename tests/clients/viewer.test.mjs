// The browser viewer in headless Chromium: an exemplar dropped on the page
// is uploaded with the API's default parameters under its file name and
// becomes ready; the list shows its name and thumbnail, and the exemplar is
// shown beside the view, with the grain the analysis detected; its slice
// fills the canvas and is not blank; the position slider and a typed far
// position change it; the oblique cut draws, another angle never shows
// half of the old cut beside the new one, and magnified it has no seams
// where tiles meet; an address edited in the open tab moves the view; the
// 3D preview draws and settles at the finest level; the texture is
// deleted; a field preset applied from the field panel switches to a
// texture that follows it, listed under its field (and another seed under
// its seed), with its arrows over the slice, and curves clicked on the
// slice make another; and the console stays free of errors. Screenshots go
// to ARTEFACTS.

import assert from "node:assert/strict";
import { mkdirSync, readFileSync } from "node:fs";
import { join } from "node:path";
import { ARTEFACTS, HERE, launch, pngStats, readyTexture, startServer } from "./browser.mjs";

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
  // The upload form's parameter controls come from the server's knob table.
  const control = (id) => page.evaluate((i) => {
    const e = document.getElementById(i);
    return e && { min: e.min, max: e.max, placeholder: e.placeholder, title: e.title };
  }, id);
  const passes = await control("p-passes");
  assert.deepEqual([passes.min, passes.max, passes.placeholder], ["0", "6", "2"], JSON.stringify(passes));
  assert.ok(passes.title.startsWith("Correction passes"), passes.title);
  assert.equal((await control("p-seed")).placeholder, "1");
  const presets = await page.evaluate(() => [...document.querySelectorAll("#p-preset option")].map((o) => o.value));
  assert.deepEqual(presets, ["", "preview", "structured"]);

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

  // The upload kept the API's defaults (so the same image has the same id
  // from any client) and stored the file's name, which the list shows with
  // a thumbnail of the exemplar.
  const { textures } = await (await fetch(`${server.base}/v1/textures`)).json();
  assert.equal(textures.length, 1);
  const again = await fetch(`${server.base}/v1/textures?name=exemplar32.png`, {
    method: "POST", headers: { "Content-Type": "image/png" }, body: readFileSync(join(HERE, "exemplar32.png")),
  });
  assert.equal((await again.json()).id, textures[0].id, "the viewer's upload did not keep the API's default parameters");
  assert.equal(textures[0].name, "exemplar32.png");
  const item = page.locator("#textures li[data-status=ready]");
  assert.equal(await item.locator(".name").textContent(), "exemplar32.png");
  await page.waitForFunction(() => {
    const img = document.querySelector("#textures li .thumb");
    return img && img.complete && img.naturalWidth > 0;
  }, null, { timeout: 10_000 });
  // The exemplar beside the view, to compare with.
  await page.waitForFunction(() => {
    const img = document.querySelector("#inset img");
    return !document.getElementById("inset").hidden && img.naturalWidth === 32;
  }, null, { timeout: 10_000 });
  assert.ok(await page.locator("#info").textContent().then((t) => t.includes(textures[0].id)), "the selected texture's id is shown");
  assert.equal(await page.locator("#params td").first().textContent(), "seed", "the selected texture's parameters are shown");
  // The grain the analysis measured on the exemplar is shown.
  assert.ok(textures[0].orientation, `no orientation in ${JSON.stringify(textures[0])}`);
  const grainText = await page.locator("#info .grain").textContent();
  assert.ok(grainText.includes(`grain ${Math.round(textures[0].orientation.grain_degrees)}°`), grainText);
  assert.ok(grainText.includes(textures[0].orientation.coherence.toFixed(2)), grainText);

  // The ready texture is selected and its slice drawn: every visible tile
  // of the level of detail that matches the screen.
  const plane = (key) => page.evaluate((k) => document.getElementById("plane").dataset[k], key);
  const waitComplete = (hud) => page.waitForFunction(
    (h) => document.getElementById("plane").dataset.complete === "1" && document.getElementById("hud").textContent.includes(h),
    hud, { timeout: 120_000 });
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
  const differs = (a, b) => {
    let changed = 0;
    for (let i = 0; i < a.length; i += 4) if (a[i] !== b[i] || a[i + 1] !== b[i + 1]) changed++;
    return changed;
  };
  await waitComplete("z = 0");
  assert.ok(Number(await plane("drawn")) > 0);
  const before = await pixels();
  const st = stats(before);
  assert.ok(st.std > 8, `slice looks blank: ${JSON.stringify(st)}`);
  // The first image fills the canvas, which fills the stage: no band of
  // background at the top or the bottom of a plain screenshot.
  const stage = await page.locator("#stage").boundingBox();
  const canvasBox = await page.locator("#plane").boundingBox();
  assert.deepEqual(canvasBox, stage);
  const shot = await page.screenshot({ clip: stage });
  for (const y of [0, Math.floor(stage.height) - 6]) {
    const band = await pngStats(browser.context, shot, { x: 0, y, w: Math.floor(stage.width), h: 6 });
    assert.ok(band.std > 4, `a band of background at y = ${y}: ${JSON.stringify(band)}`);
  }
  await page.screenshot({ path: join(ARTEFACTS, "viewer-slice.png") });

  // Move the slider: a new slice is drawn and differs.
  await page.locator("#position").fill("41");
  await waitComplete("z = 41");
  const after = await pixels();
  assert.ok(differs(before, after) > before.length / 4 / 4, `the slice hardly changed (${differs(before, after)} pixels)`);
  assert.equal(await page.locator("#at").inputValue(), "41");
  await page.screenshot({ path: join(ARTEFACTS, "viewer-slice-moved.png") });

  // Type a far position: the slice there is drawn, not blank, and new.
  await page.locator("#at").fill("1000000");
  await page.locator("#at").press("Enter");
  await waitComplete("z = 1000000");
  const far = await pixels();
  assert.ok(stats(far).std > 8, `the far slice looks blank: ${JSON.stringify(stats(far))}`);
  assert.ok(differs(after, far) > far.length / 4 / 4, "the far slice hardly differs");
  assert.equal(Number(await page.locator("#position").inputValue()), 1000000, "the slider follows the typed position");
  // The address names the view, so that it can be bookmarked.
  await page.waitForFunction(() => /[#&]p=1000000(&|$)/.test(location.hash) && /[#&]a=z(&|$)/.test(location.hash));
  await page.screenshot({ path: join(ARTEFACTS, "viewer-slice-far.png") });

  // Keyboard: the y axis, then the oblique cut.
  await page.locator("#plane").focus();
  await page.keyboard.press("y");
  await waitComplete("y = 1000000");
  assert.equal(await page.locator("#axis").inputValue(), "y");
  await page.keyboard.press("c");
  await waitComplete("yaw 30°");
  assert.ok(stats(await pixels()).std > 8, "cut looks blank");
  await page.screenshot({ path: join(ARTEFACTS, "viewer-cut.png") });

  // Another cut angle: each frame until the new cut is whole shows the old
  // cut whole or the new one (coarse at first), never half of each.
  const shares = await page.evaluate(() => new Promise((done) => {
    const c = document.getElementById("plane");
    const ctx = c.getContext("2d");
    const old = ctx.getImageData(0, 0, c.width, c.height).data;
    const yaw = document.getElementById("yaw");
    yaw.value = "75";
    yaw.dispatchEvent(new Event("input"));
    yaw.dispatchEvent(new Event("change"));
    const out = [];
    const t0 = performance.now();
    const poll = () => {
      const d = ctx.getImageData(0, 0, c.width, c.height).data;
      let same = 0;
      for (let i = 0; i < d.length; i += 4) if (d[i] === old[i] && d[i + 1] === old[i + 1] && d[i + 2] === old[i + 2]) same++;
      out.push(same / (d.length / 4));
      if (c.dataset.complete === "1" || performance.now() - t0 > 60_000) done(out);
      else requestAnimationFrame(poll);
    };
    requestAnimationFrame(poll);
  }));
  await waitComplete("yaw 75°");
  const mixed = shares.filter((f) => f > 0.15 && f < 0.85);
  assert.deepEqual(mixed, [], `frames with old and new cut side by side (share of old pixels per frame: ${shares.map((f) => f.toFixed(2)).join(" ")})`);

  // Magnified 4 times, the cut is smoothed as one image: no step in the
  // column or row differences where tiles meet.
  await page.evaluate(() => window.solidtex.setView({ scale: 4, center: [256 + 23, 256 + 17] }));
  await waitComplete("yaw 75°");
  const seams = await page.evaluate(() => {
    const c = document.getElementById("plane");
    const { data } = c.getContext("2d").getImageData(0, 0, c.width, c.height);
    const W = c.width, H = c.height, st = window.solidtex.state;
    const lum = (x, y) => { const i = 4 * (y * W + x); return data[i] + data[i + 1] + data[i + 2]; };
    // Mean |difference| between neighbours across each column (rows) gap.
    const across = (n, m, at) => {
      const d = [];
      for (let a = 0; a + 1 < n; a++) {
        let s = 0;
        for (let b = 0; b < m; b++) s += Math.abs(at(a + 1, b) - at(a, b));
        d.push(s / m);
      }
      return d;
    };
    const median = (d) => d.slice().sort((p, q) => p - q)[Math.floor(d.length / 2)];
    const ps = st.scale * Math.max(1, Math.min(2, window.devicePixelRatio || 1));
    const xb = Math.round((256 - st.center[0]) * ps + W / 2), yb = Math.round((256 - st.center[1]) * ps + H / 2);
    const dx = across(W, H, (x, y) => lum(x, y)), dy = across(H, W, (y, x) => lum(x, y));
    const peak = (d, b) => Math.max(...d.slice(b - 3, b + 2));
    return { x: peak(dx, xb) / median(dx), y: peak(dy, yb) / median(dy), xb, yb };
  });
  assert.ok(seams.x < 2 && seams.y < 2, `seams where the cut's tiles meet: ${JSON.stringify(seams)}`);
  await page.screenshot({ path: join(ARTEFACTS, "viewer-cut-magnified.png") });

  // An address edited in the open tab moves the view there.
  const tid = textures[0].id;
  await page.evaluate((id) => { location.hash = `#t=${id}&m=slice&a=x&p=123&c=5,6&s=2&yaw=30&pitch=35`; }, tid);
  await waitComplete("x = 123");
  assert.equal(await page.locator("#axis").inputValue(), "x");
  assert.equal(await page.locator("#at").inputValue(), "123");
  await page.keyboard.press("c");
  await waitComplete("yaw 30°");

  // The raw brick link points at a 64³ region around the view centre.
  const raw = await page.locator("#download-raw").getAttribute("href");
  assert.match(raw, /region\.raw\?x=-?\d+&y=-?\d+&z=-?\d+&w=64&h=64&d=64&lod=\d+$/);
  assert.match(await page.locator("#download-raw").getAttribute("title"), /x varies fastest/);

  // The 3D preview: a carved sphere, then a deeper cut redraws it.
  await page.keyboard.press("v");
  await page.waitForFunction(() => Number(document.getElementById("solid").dataset.drawn) > 0, null, { timeout: 120_000 });
  // It settles at the finest level (the coarsest only stands in meanwhile).
  await page.waitForFunction(() => document.getElementById("solid").dataset.lod === "0" && /· lod 0 ·/.test(document.getElementById("hud").textContent), null, { timeout: 120_000 });
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

  // Delete the texture (confirming the dialog): the list is empty again.
  page.once("dialog", (d) => d.accept());
  await page.locator("#delete").click();
  await page.waitForFunction(() => document.querySelectorAll("#textures li").length === 0, null, { timeout: 10_000 });
  await page.waitForFunction(() => /deleted/.test(document.getElementById("status").textContent));
  assert.equal((await (await fetch(`${server.base}/v1/textures`)).json()).textures.length, 0);

  // The field panel: a texture selected again, a slant preset applied
  // makes the viewer switch to a variant that follows it, keeping the
  // view, and draws its local x arrows at the slant's angle.
  const base = await readyTexture(server.base, join(HERE, "exemplar32.png"), "name=field.png");
  await page.waitForFunction((id) => window.solidtex.state.selected && window.solidtex.state.selected.id === id, base.id, { timeout: 10_000 });
  await page.keyboard.press("s");
  await page.keyboard.press("z");
  await page.locator("#at").fill("0");
  await page.locator("#at").press("Enter");
  await waitComplete("z = 0");
  const unguided = await pixels();
  await page.locator("#field-panel summary").click();
  assert.match(await page.locator("#f-current").textContent(), /no field/);
  await page.locator("#f-kind").selectOption("slant");
  assert.ok(await page.locator("#f-angle").isVisible(), "the slant's angle is offered");
  assert.ok(!(await page.locator("#f-period").isVisible()), "the zigzag's period is not");
  await page.locator("#f-angle").fill("40");
  await page.locator("#f-arrows").check();
  // Without a field the arrows follow the world's x axis.
  await page.waitForFunction(() => Number(document.getElementById("overlay").dataset.arrows) > 0, null, { timeout: 30_000 });
  await page.locator("#f-apply").click();
  await page.waitForFunction((id) => {
    const t = window.solidtex.state.selected;
    return t && t.id !== id && t.params.field && t.status === "ready";
  }, base.id, { timeout: 60_000 });
  const slanted = await page.evaluate(() => window.solidtex.state.selected);
  assert.deepEqual(slanted.params.field, { kind: "slant", angle: 40 });
  const variant = await (await fetch(`${server.base}/v1/textures/${base.id}/variants`, {
    method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ field: "slant:40" }),
  })).json();
  assert.equal(variant.id, slanted.id, "the viewer's variant is the API's");
  assert.match(await page.locator("#f-current").textContent(), /slant 40°/);
  // The variant is listed under its field, not under its base's name alone;
  // another seed of the same image and name says its seed.
  await readyTexture(server.base, join(HERE, "exemplar32.png"), "name=field.png&seed=7");
  await page.waitForFunction(() => document.querySelectorAll("#textures li").length === 3, null, { timeout: 10_000 });
  const names = await page.locator("#textures li .name").allTextContents();
  assert.equal(new Set(names).size, 3, `names alike: ${JSON.stringify(names)}`);
  assert.ok(names.includes("field.png · slant 40°"), JSON.stringify(names));
  assert.ok(names.includes("field.png · seed 7"), JSON.stringify(names));
  await page.waitForFunction((id) => location.hash.includes(`t=${id}`), slanted.id, { timeout: 10_000 });
  await waitComplete("z = 0");
  const guided = await pixels();
  assert.ok(differs(unguided, guided) > guided.length / 4 / 4, "the slice did not change with the field");
  // Arrows of the new texture, drawn at 40° on the screen (v down).
  await page.waitForFunction(() => Number(document.getElementById("overlay").dataset.arrows) > 4, null, { timeout: 30_000 });
  const overlay = await page.evaluate(() => {
    const c = document.getElementById("overlay");
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    let drawn = 0, accent = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (d[i + 3] > 0) drawn++;
      if (d[i + 3] > 200 && d[i] > 180 && d[i + 1] > 120 && d[i + 2] < 110) accent++;
    }
    return { drawn, accent, pixels: d.length / 4 };
  });
  assert.ok(overlay.accent > 200, `no arrows on the overlay: ${JSON.stringify(overlay)}`);
  assert.ok(overlay.drawn < overlay.pixels / 3, `the overlay hides the slice: ${JSON.stringify(overlay)}`);
  const angle = await page.evaluate(async (id) => {
    const f = await (await fetch(`/v1/textures/${id}/frames/z/0.json?w=1&h=1`)).json();
    return (Math.atan2(f.samples[0].x[1], f.samples[0].x[0]) * 180) / Math.PI;
  }, slanted.id);
  assert.ok(Math.abs(angle - 40) < 1e-3, `arrows at ${angle}°`);
  await page.screenshot({ path: join(ARTEFACTS, "viewer-field-slant.png") });

  // Curves: two clicks draw a curve on the slice, Apply makes a texture
  // that follows it.
  await page.locator("#f-kind").selectOption("sketch");
  assert.equal(await page.locator("#f-draw").getAttribute("aria-pressed"), "true");
  const stageBox = await page.locator("#plane").boundingBox();
  await page.mouse.click(stageBox.x + stageBox.width * 0.3, stageBox.y + stageBox.height * 0.6);
  await page.mouse.click(stageBox.x + stageBox.width * 0.7, stageBox.y + stageBox.height * 0.4);
  await page.waitForFunction(() => document.getElementById("overlay").dataset.points === "2");
  const curve = await page.evaluate(() => window.solidtex.state.field.curves[0]);
  assert.equal(curve.points.length, 2);
  assert.deepEqual(curve.normal, [0, 0, 1]);
  assert.ok(curve.points.every((p) => p[2] === 0), "the points lie on the slice z = 0");
  assert.ok(curve.points[1][0] > curve.points[0][0] && curve.points[1][1] < curve.points[0][1], JSON.stringify(curve));
  await page.locator("#f-apply").click();
  await page.waitForFunction((id) => {
    const t = window.solidtex.state.selected;
    return t && t.id !== id && t.params.field && t.params.field.kind === "sketch" && t.status === "ready";
  }, slanted.id, { timeout: 60_000 });
  await waitComplete("z = 0");
  await page.waitForFunction(() => Number(document.getElementById("overlay").dataset.arrows) > 4, null, { timeout: 30_000 });
  await page.screenshot({ path: join(ARTEFACTS, "viewer-field-sketch.png") });

  assert.deepEqual(errors, [], "console errors");
  console.log("viewer: ok");
} finally {
  if (browser) await browser.close();
  await server.stop();
}
