// The solidtex viewer: plain JavaScript over the public HTTP API.
//
// - The texture list polls `/v1/textures`; an exemplar dropped on the page
//   is uploaded as `image/png` and its precompute progress followed.
// - Slice and cut views draw PNGs from `slices/{axis}/{at}.png` and
//   `cut.png` on a 2D canvas. While the view moves they ask for a coarse
//   level of detail (cheap, mostly cached); once it rests they refine level
//   by level down to the one that matches the screen.
// - The 3D preview fetches one brick as raw RGB8 into a WebGL2 3D texture
//   and ray-casts a carved shape (cube or sphere, cut by a plane) through
//   it, so every face shows the solid texture.
"use strict";

const API = "/v1/textures";
const $ = (id) => document.getElementById(id);

const state = {
  textures: [],
  selected: null, // texture view (JSON) of the selected texture
  mode: "slice",
  axis: "z",
  position: 0, // slice position / cut offset, finest voxels
  center: [0, 0], // view centre in plane coordinates, finest voxels
  scale: 4, // screen pixels per finest voxel
  yaw: 30,
  pitch: 35,
  shape: "sphere",
  carve: 0.1,
  blockLod: null,
  orbit: { yaw: -35, pitch: 25, distance: 3.6 },
  uploading: null, // id of a texture being precomputed after an upload
};

// ---------------------------------------------------------------------
// Status line

function say(text, isError) {
  const s = $("status");
  s.textContent = text;
  s.classList.toggle("error", !!isError);
}

async function errorText(res) {
  try {
    const v = await res.json();
    return v.error ? `${v.error.code}: ${v.error.message}` : res.statusText;
  } catch (_) {
    return `${res.status} ${res.statusText}`;
  }
}

// ---------------------------------------------------------------------
// Texture list and upload

async function refreshList() {
  let res;
  try {
    res = await fetch(API, { cache: "no-store" });
  } catch (_) {
    say("server unreachable; retrying", true);
    return;
  }
  if (!res.ok) return;
  const v = await res.json();
  // Re-render only on change, so that keyboard focus in the list stays.
  const changed = JSON.stringify(v.textures) !== JSON.stringify(state.textures);
  state.textures = v.textures;
  if (changed) renderList();
  if (state.selected) {
    const now = state.textures.find((t) => t.id === state.selected.id);
    if (!now) {
      select(null);
    } else if (now.status !== state.selected.status) {
      select(now);
    }
  } else {
    const first = state.textures.find((t) => t.status === "ready");
    if (first) select(first);
  }
  if (state.uploading) {
    const t = state.textures.find((t) => t.id === state.uploading);
    if (t && t.status === "ready") {
      say(`texture ${t.id.slice(0, 8)} is ready (${(t.precompute_seconds || 0).toFixed(1)} s)`);
      state.uploading = null;
      select(t);
    } else if (t && t.status === "failed") {
      say(`precompute failed: ${t.reason}`, true);
      state.uploading = null;
    } else if (t) {
      say(`precomputing ${t.id.slice(0, 8)}: ${t.stage} ${(t.progress * 100).toFixed(0)}%`);
    }
  }
}

function renderList() {
  const ul = $("textures");
  ul.textContent = "";
  for (const t of state.textures) {
    const li = document.createElement("li");
    li.tabIndex = 0;
    li.dataset.id = t.id;
    li.dataset.status = t.status;
    if (state.selected && state.selected.id === t.id) li.classList.add("selected");
    const id = document.createElement("div");
    id.className = "id";
    id.textContent = t.id.length > 20 ? t.id.slice(0, 16) + "…" : t.id;
    const meta = document.createElement("div");
    meta.className = "meta";
    const size = `${t.exemplar.width}×${t.exemplar.height}`;
    meta.textContent =
      t.status === "ready" ? `${size} · ready · lod 0–${t.max_lod}`
        : t.status === "failed" ? `${size} · failed`
          : `${size} · ${t.stage} ${(t.progress * 100).toFixed(0)}%`;
    li.append(id, meta);
    if (t.status === "pending") {
      const bar = document.createElement("div");
      bar.className = "bar";
      const fill = document.createElement("div");
      fill.style.width = `${(t.progress * 100).toFixed(1)}%`;
      bar.append(fill);
      li.append(bar);
    }
    li.title = t.status === "failed" ? t.reason : t.id;
    li.addEventListener("click", () => select(t));
    li.addEventListener("keydown", (e) => {
      if (e.key === "Enter" || e.key === " ") {
        e.preventDefault();
        select(t);
      }
    });
    ul.append(li);
  }
}

function select(t) {
  const changed = !state.selected || !t || state.selected.id !== t.id;
  state.selected = t;
  renderList();
  $("current").textContent = t ? `${t.id} · ${t.status}` : "";
  if (!t || t.status !== "ready") {
    plane.clear(t ? `texture ${t.status}` : "no texture");
    solid.clear();
    return;
  }
  const lodSel = $("block-lod");
  if (changed || lodSel.options.length !== t.max_lod + 1) {
    lodSel.textContent = "";
    for (let k = t.max_lod; k >= 0; k--) {
      const o = document.createElement("option");
      o.value = String(k);
      o.textContent = `lod ${k}`;
      lodSel.append(o);
    }
    state.blockLod = t.max_lod;
    lodSel.value = String(t.max_lod);
  }
  plane.invalidate(true);
  solid.invalidate();
}

async function upload(file) {
  if (!file) return;
  if (file.type && file.type !== "image/png") {
    say(`${file.name}: only PNG exemplars are accepted`, true);
    return;
  }
  const levels = $("levels").value;
  say(`uploading ${file.name}…`);
  let res;
  try {
    res = await fetch(`${API}?levels=${encodeURIComponent(levels)}`, {
      method: "POST",
      headers: { "Content-Type": "image/png" },
      body: file,
    });
  } catch (e) {
    say(`upload failed: ${e.message}`, true);
    return;
  }
  if (!res.ok) {
    say(`upload refused: ${await errorText(res)}`, true);
    return;
  }
  const t = await res.json();
  state.uploading = t.id;
  say(t.status === "ready" ? `texture ${t.id.slice(0, 8)} is known already` : `precomputing ${t.id.slice(0, 8)}…`);
  await refreshList();
  const now = state.textures.find((x) => x.id === t.id);
  if (now) select(now);
}

function setupUpload() {
  const drop = $("drop");
  const input = $("file");
  drop.addEventListener("click", (e) => {
    if (e.target.tagName !== "INPUT") input.click();
  });
  drop.addEventListener("keydown", (e) => {
    if (e.key === "Enter" || e.key === " ") {
      e.preventDefault();
      input.click();
    }
  });
  input.addEventListener("change", () => upload(input.files[0]));
  for (const ev of ["dragenter", "dragover"]) {
    drop.addEventListener(ev, (e) => {
      e.preventDefault();
      drop.classList.add("over");
    });
  }
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    const f = e.dataTransfer && e.dataTransfer.files[0];
    upload(f);
  });
  // A file dropped anywhere else should not navigate away.
  window.addEventListener("dragover", (e) => e.preventDefault());
  window.addEventListener("drop", (e) => e.preventDefault());
}

// ---------------------------------------------------------------------
// Slice and cut views

/// Rotation of the cut plane: columns u, v (in the plane) and n (normal).
function cutBasis() {
  const y = (state.yaw * Math.PI) / 180;
  const p = (state.pitch * Math.PI) / 180;
  const cy = Math.cos(y), sy = Math.sin(y), cp = Math.cos(p), sp = Math.sin(p);
  const u = [cy, 0, -sy];
  const v = [sy * sp, cp, cy * sp];
  const n = [sy * cp, -sp, cy * cp];
  return { u, v, n };
}

const plane = (() => {
  const canvas = $("plane");
  const ctx = canvas.getContext("2d");
  let shown = null; // { img, key, x0, y0, pxPerVoxel (finest units), lod }
  let controller = null;
  let settleTimer = null;
  let coarseTimer = null;
  let generation = 0;
  canvas.dataset.drawn = "0";

  function size() {
    const r = canvas.getBoundingClientRect();
    const w = Math.max(1, Math.round(r.width)), h = Math.max(1, Math.round(r.height));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
    return [w, h];
  }

  function targetLod() {
    const t = state.selected;
    const lod = Math.floor(Math.log2(1 / state.scale) + 1e-9);
    return Math.max(0, Math.min(t.max_lod, lod));
  }

  // The request for the current view at `lod`, with `coarse` asking for
  // fewer pixels in a cut.
  function request(lod, coarse) {
    const t = state.selected;
    const [W, H] = size();
    const k = 2 ** lod;
    if (state.mode === "slice") {
      const s = state.scale * k; // screen px per lod voxel
      const u0 = Math.floor((state.center[0] - W / 2 / state.scale) / k);
      const v0 = Math.floor((state.center[1] - H / 2 / state.scale) / k);
      const w = Math.min(4096, Math.ceil(W / s) + 2);
      const h = Math.min(4096, Math.ceil(H / s) + 2);
      const at = Math.floor(state.position / k);
      const url = `${API}/${t.id}/slices/${state.axis}/${at}.png?u0=${u0}&v0=${v0}&w=${w}&h=${h}&lod=${lod}`;
      return { url, lod, place: { x0: u0 * k, y0: v0 * k, per: k } };
    }
    // Screen px per image px: a cut is filtered, so half the screen's
    // resolution is enough once a voxel spans two pixels or more.
    const r = coarse ? 4 : state.scale >= 2 ? 2 : 1;
    const w = Math.max(1, Math.ceil(W / r)), h = Math.max(1, Math.ceil(H / r));
    const step = r / state.scale / k; // lod voxels per image px
    const { u, v, n } = cutBasis();
    const cx = state.center[0], cy = state.center[1];
    const o = [0, 1, 2].map((a) =>
      (n[a] * state.position + u[a] * (cx - (W / 2) / state.scale) + v[a] * (cy - (H / 2) / state.scale)) / k);
    const f = (a) => a.map((x) => +x.toFixed(6)).join(",");
    const url = `${API}/${t.id}/cut.png?origin=${f(o)}&u=${f(u.map((x) => x * step))}&v=${f(v.map((x) => x * step))}` +
      `&w=${w}&h=${h}&lod=${lod}&filter=trilinear`;
    return { url, lod, place: { x0: cx - W / 2 / state.scale, y0: cy - H / 2 / state.scale, per: r / state.scale, cut: true } };
  }

  function draw() {
    const [W, H] = size();
    ctx.fillStyle = "#0d0e10";
    ctx.fillRect(0, 0, W, H);
    if (!shown) return;
    const { img, place } = shown;
    ctx.imageSmoothingEnabled = !!place.cut;
    // Screen position of the image's corner, in the current view.
    const sx = (place.x0 - state.center[0]) * state.scale + W / 2;
    const sy = (place.y0 - state.center[1]) * state.scale + H / 2;
    const sw = img.width * place.per * state.scale;
    const sh = img.height * place.per * state.scale;
    ctx.drawImage(img, sx, sy, sw, sh);
  }

  async function fetchImage(req, signal) {
    const res = await fetch(req.url, { signal });
    if (!res.ok) throw new Error(await errorText(res));
    const blob = await res.blob();
    return await createImageBitmap(blob);
  }

  // Fetches `levels` one after the other, drawing each as it arrives,
  // until a newer view cancels them.
  async function load(levels, coarse) {
    if (controller) controller.abort();
    controller = new AbortController();
    const signal = controller.signal;
    const my = ++generation;
    for (const lod of levels) {
      const req = request(lod, coarse && lod === levels[0]);
      const key = `${state.mode}|${req.url}`;
      if (shown && shown.key === key) continue;
      hud(`lod ${lod}…`);
      let img;
      try {
        img = await fetchImage(req, signal);
      } catch (e) {
        if (e.name === "AbortError" || signal.aborted) return;
        say(`could not draw: ${e.message}`, true);
        return;
      }
      if (my !== generation) return;
      shown = { img, key, place: req.place, lod, mode: state.mode };
      draw();
      canvas.dataset.drawn = String(Number(canvas.dataset.drawn) + 1);
      canvas.dataset.lod = String(lod);
      hud(`lod ${lod}${lod === levels[levels.length - 1] ? "" : " · refining"}`);
    }
    canvas.dataset.settled = String(my);
  }

  function hud(text) {
    const t = state.selected;
    const where = state.mode === "slice" ? `${state.axis} = ${state.position}` : `yaw ${state.yaw}° pitch ${state.pitch}° offset ${state.position}`;
    $("hud").textContent = `${t.id.slice(0, 8)} · ${where} · centre ${state.center.map((c) => c.toFixed(0)).join(", ")} · ${state.scale.toFixed(2)} px/voxel · ${text}`;
  }

  // Redraws what is shown at once, asks for a coarse image now and
  // refines once the view has rested.
  function invalidate(immediate) {
    if (!state.selected || state.selected.status !== "ready" || state.mode === "solid") return;
    if (shown && shown.mode !== state.mode) shown = null;
    draw();
    const fine = targetLod();
    const coarse = Math.min(state.selected.max_lod, fine + 2);
    clearTimeout(settleTimer);
    if (immediate) {
      clearTimeout(coarseTimer);
      coarseTimer = null;
      const levels = [];
      for (let l = coarse; l >= fine; l--) levels.push(l);
      load(levels, false);
      return;
    }
    // At most one coarse request per frame or so while dragging.
    if (!coarseTimer) {
      coarseTimer = setTimeout(() => {
        coarseTimer = null;
        load([Math.min(state.selected.max_lod, targetLod() + 2)], true);
      }, 50);
    }
    settleTimer = setTimeout(() => {
      const levels = [];
      for (let l = coarse; l >= fine; l--) levels.push(l);
      load(levels, false);
    }, 300);
  }

  function clear(text) {
    if (controller) controller.abort();
    shown = null;
    draw();
    $("hud").textContent = text || "";
  }

  // Mouse and keyboard.
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    canvas.focus();
    drag = { x: e.clientX, y: e.clientY, c: state.center.slice() };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    state.center = [drag.c[0] - (e.clientX - drag.x) / state.scale, drag.c[1] - (e.clientY - drag.y) / state.scale];
    invalidate(false);
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const r = canvas.getBoundingClientRect();
    const mx = e.clientX - r.left - r.width / 2, my = e.clientY - r.top - r.height / 2;
    const before = [state.center[0] + mx / state.scale, state.center[1] + my / state.scale];
    state.scale = Math.max(1 / 64, Math.min(32, state.scale * Math.exp(-e.deltaY * 0.0015)));
    state.center = [before[0] - mx / state.scale, before[1] - my / state.scale];
    invalidate(false);
  }, { passive: false });
  window.addEventListener("resize", () => invalidate(false));

  return { invalidate, clear, draw, pan(dx, dy) { state.center[0] += dx / state.scale; state.center[1] += dy / state.scale; invalidate(false); }, zoom(f) { state.scale = Math.max(1 / 64, Math.min(32, state.scale * f)); invalidate(false); } };
})();

// ---------------------------------------------------------------------
// 3D preview (WebGL2 ray casting through one brick)

const solid = (() => {
  const canvas = $("solid");
  let gl = null, prog = null, tex = null, loaded = null, controller = null, uniforms = {};
  canvas.dataset.drawn = "0";

  const VS = `#version 300 es
    in vec2 corner;
    out vec2 ndc;
    void main() { ndc = corner; gl_Position = vec4(corner, 0.0, 1.0); }`;
  // The object lives in [-1, 1]^3: the box, optionally a sphere inside
  // it, cut by the half-space dot(n, p) <= d. A ray enters a convex
  // intersection at the latest of its entries; that surface's normal
  // shades it.
  const FS = `#version 300 es
    precision highp float;
    precision highp sampler3D;
    in vec2 ndc;
    out vec4 color;
    uniform sampler3D volume;
    uniform vec3 eye, right, up, fwd;
    uniform float aspect, sphere, carve;
    uniform vec3 cutNormal;
    void main() {
      vec3 dir = normalize(fwd + ndc.x * aspect * 0.55 * right + ndc.y * 0.55 * up);
      vec3 inv = 1.0 / dir;
      vec3 t0 = (vec3(-1.0) - eye) * inv, t1 = (vec3(1.0) - eye) * inv;
      vec3 tmin = min(t0, t1), tmax = max(t0, t1);
      float enter = max(max(tmin.x, tmin.y), tmin.z);
      float leave = min(min(tmax.x, tmax.y), tmax.z);
      vec3 normal = enter == tmin.x ? vec3(-sign(dir.x), 0.0, 0.0)
                  : enter == tmin.y ? vec3(0.0, -sign(dir.y), 0.0)
                  : vec3(0.0, 0.0, -sign(dir.z));
      if (sphere > 0.5) {
        float b = dot(eye, dir), c = dot(eye, eye) - 0.98;
        float h = b * b - c;
        if (h < 0.0) { color = vec4(0.08, 0.085, 0.1, 1.0); return; }
        float s0 = -b - sqrt(h), s1 = -b + sqrt(h);
        if (s0 > enter) { enter = s0; normal = normalize(eye + s0 * dir); }
        leave = min(leave, s1);
      }
      float dn = dot(cutNormal, dir), on = dot(cutNormal, eye);
      if (abs(dn) < 1e-6) {
        if (on > carve) leave = -1.0;
      } else {
        float tc = (carve - on) / dn;
        if (dn < 0.0) { if (tc > enter) { enter = tc; normal = cutNormal; } }
        else leave = min(leave, tc);
      }
      if (enter >= leave || leave <= 0.0) { color = vec4(0.08, 0.085, 0.1, 1.0); return; }
      vec3 p = eye + max(enter, 0.0) * dir;
      vec3 rgb = texture(volume, clamp(p * 0.5 + 0.5, 0.0, 1.0)).rgb;
      float light = 0.45 + 0.55 * max(dot(normal, -dir), 0.0);
      color = vec4(rgb * light, 1.0);
    }`;

  function init() {
    if (gl) return true;
    gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true });
    if (!gl) return false;
    const sh = (type, src) => {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    };
    prog = gl.createProgram();
    gl.attachShader(prog, sh(gl.VERTEX_SHADER, VS));
    gl.attachShader(prog, sh(gl.FRAGMENT_SHADER, FS));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
    gl.useProgram(prog);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
    const loc = gl.getAttribLocation(prog, "corner");
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
    for (const n of ["volume", "eye", "right", "up", "fwd", "aspect", "sphere", "carve", "cutNormal"]) {
      uniforms[n] = gl.getUniformLocation(prog, n);
    }
    tex = gl.createTexture();
    return true;
  }

  function render() {
    if (!gl || !loaded) return;
    const r = canvas.getBoundingClientRect();
    const w = Math.max(1, Math.round(r.width)), h = Math.max(1, Math.round(r.height));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
    gl.viewport(0, 0, w, h);
    const o = state.orbit;
    const cy = Math.cos((o.yaw * Math.PI) / 180), sy = Math.sin((o.yaw * Math.PI) / 180);
    const cp = Math.cos((o.pitch * Math.PI) / 180), sp = Math.sin((o.pitch * Math.PI) / 180);
    // The camera orbits the block; at rest it looks along +z with x to the
    // right and y downwards, as the z slices are drawn.
    const eye = [o.distance * cp * sy, -o.distance * sp, -o.distance * cp * cy];
    const fwd = eye.map((x) => -x / o.distance);
    const right = [cy, 0, sy];
    const up = [
      right[1] * fwd[2] - right[2] * fwd[1],
      right[2] * fwd[0] - right[0] * fwd[2],
      right[0] * fwd[1] - right[1] * fwd[0],
    ];
    gl.uniform3fv(uniforms.eye, eye);
    gl.uniform3fv(uniforms.fwd, fwd);
    gl.uniform3fv(uniforms.right, right);
    gl.uniform3fv(uniforms.up, up);
    gl.uniform1f(uniforms.aspect, w / h);
    gl.uniform1f(uniforms.sphere, state.shape === "sphere" ? 1 : 0);
    gl.uniform1f(uniforms.carve, state.carve * 1.8);
    // The carved-away side faces the default camera.
    const { n } = cutBasis();
    gl.uniform3fv(uniforms.cutNormal, n.map((x) => -x));
    gl.uniform1i(uniforms.volume, 0);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    canvas.dataset.drawn = String(Number(canvas.dataset.drawn) + 1);
  }

  // Loads the brick that holds the slice view's centre at the chosen
  // level of detail.
  async function invalidate() {
    const t = state.selected;
    if (!t || t.status !== "ready" || state.mode !== "solid") return;
    try {
      if (!init()) {
        say("WebGL2 is not available in this browser: the 3D preview is off", true);
        return;
      }
    } catch (e) {
      say(`WebGL setup failed: ${e.message}`, true);
      return;
    }
    const lod = state.blockLod ?? t.max_lod;
    const e = t.brick_size, k = 2 ** lod;
    const c = { x: 0, y: 0, z: 0 };
    const frame = { z: ["x", "y"], x: ["y", "z"], y: ["z", "x"] }[state.axis];
    c[frame[0]] = state.center[0];
    c[frame[1]] = state.center[1];
    c[state.axis] = state.position;
    const b = ["x", "y", "z"].map((a) => Math.floor(c[a] / k / e));
    const key = `${t.id}/${lod}/${b.join("_")}`;
    if (loaded === key) {
      render();
      return;
    }
    if (controller) controller.abort();
    controller = new AbortController();
    $("hud").textContent = `loading brick ${b.join(", ")} at lod ${lod} (${e}³ voxels)…`;
    let data;
    try {
      const res = await fetch(`${API}/${t.id}/bricks/${lod}/${b.join("_")}.raw`, { signal: controller.signal });
      if (!res.ok) throw new Error(await errorText(res));
      data = new Uint8Array(await res.arrayBuffer());
    } catch (err) {
      if (err.name !== "AbortError") say(`could not load the brick: ${err.message}`, true);
      return;
    }
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_3D, tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGB8, e, e, e, 0, gl.RGB, gl.UNSIGNED_BYTE, data);
    gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    for (const w of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) {
      gl.texParameteri(gl.TEXTURE_3D, w, gl.CLAMP_TO_EDGE);
    }
    loaded = key;
    $("hud").textContent = `brick ${b.join(", ")} · lod ${lod} · ${e}³ voxels · drag to orbit, wheel to zoom`;
    render();
  }

  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    canvas.focus();
    drag = { x: e.clientX, y: e.clientY, yaw: state.orbit.yaw, pitch: state.orbit.pitch };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    state.orbit.yaw = drag.yaw - (e.clientX - drag.x) * 0.4;
    state.orbit.pitch = Math.max(-89, Math.min(89, drag.pitch + (e.clientY - drag.y) * 0.4));
    render();
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    state.orbit.distance = Math.max(1.8, Math.min(8, state.orbit.distance * Math.exp(e.deltaY * 0.001)));
    render();
  }, { passive: false });
  window.addEventListener("resize", render);

  function clear() {
    loaded = null;
    if (gl) {
      gl.clearColor(0.08, 0.085, 0.1, 1);
      gl.clear(gl.COLOR_BUFFER_BIT);
    }
  }

  return { invalidate, render, clear, orbit(dy, dp) { state.orbit.yaw += dy; state.orbit.pitch = Math.max(-89, Math.min(89, state.orbit.pitch + dp)); render(); } };
})();

// ---------------------------------------------------------------------
// Controls

function setMode(mode) {
  state.mode = mode;
  for (const b of document.querySelectorAll("nav .tab")) b.classList.toggle("active", b.dataset.mode === mode);
  for (const l of document.querySelectorAll(".controls label")) {
    l.hidden = !l.dataset.for.split(" ").includes(mode);
  }
  $("plane").hidden = mode === "solid";
  $("solid").hidden = mode !== "solid";
  if (mode === "solid") solid.invalidate();
  else plane.invalidate(true);
}

function bindRange(id, apply, fmt) {
  const input = $(id), out = $(`${id}-out`);
  const update = (settled) => {
    apply(Number(input.value));
    if (out) out.textContent = fmt ? fmt(Number(input.value)) : input.value;
    if (state.mode === "solid") {
      if (id === "position") solid.invalidate();
      else solid.render();
    } else {
      plane.invalidate(settled);
    }
  };
  input.addEventListener("input", () => update(false));
  input.addEventListener("change", () => update(true));
}

function setPosition(p) {
  state.position = p;
  $("position").value = String(p);
  $("position-out").textContent = String(p);
}

function setupControls() {
  for (const b of document.querySelectorAll("nav .tab")) b.addEventListener("click", () => setMode(b.dataset.mode));
  $("axis").addEventListener("change", () => {
    state.axis = $("axis").value;
    plane.invalidate(true);
  });
  bindRange("position", (v) => { state.position = v; });
  bindRange("yaw", (v) => { state.yaw = v; });
  bindRange("pitch", (v) => { state.pitch = v; });
  bindRange("carve", (v) => { state.carve = v / 100; }, (v) => (v / 100).toFixed(2));
  $("shape").addEventListener("change", () => {
    state.shape = $("shape").value;
    solid.render();
  });
  $("block-lod").addEventListener("change", () => {
    state.blockLod = Number($("block-lod").value);
    solid.invalidate();
  });
  window.addEventListener("keydown", (e) => {
    const tag = e.target.tagName;
    if (tag === "INPUT" || tag === "SELECT" || tag === "TEXTAREA") return;
    const k = e.key.toLowerCase();
    const step = e.shiftKey ? 16 : 1;
    if (k === "s") setMode("slice");
    else if (k === "c") setMode("cut");
    else if (k === "v") setMode("solid");
    else if ("xyz".includes(k) && k.length === 1) {
      state.axis = k;
      $("axis").value = k;
      plane.invalidate(true);
    } else if (k === "[" || k === "pagedown") {
      setPosition(state.position - step);
      state.mode === "solid" ? solid.invalidate() : plane.invalidate(false);
    } else if (k === "]" || k === "pageup") {
      setPosition(state.position + step);
      state.mode === "solid" ? solid.invalidate() : plane.invalidate(false);
    } else if (k.startsWith("arrow")) {
      e.preventDefault();
      const d = { arrowleft: [-1, 0], arrowright: [1, 0], arrowup: [0, -1], arrowdown: [0, 1] }[k];
      if (state.mode === "solid") solid.orbit(d[0] * 5, d[1] * 5);
      else plane.pan(d[0] * 40, d[1] * 40);
    } else if (k === "+" || k === "=") {
      plane.zoom(1.25);
    } else if (k === "-") {
      plane.zoom(0.8);
    }
  });
}

// Exposed for tests and for poking at from the console.
window.solidtex = { state, select, setMode, upload };

setupUpload();
setupControls();
setMode("slice");
refreshList();
setInterval(refreshList, 1000);
