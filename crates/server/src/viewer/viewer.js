// The solidtex viewer: plain JavaScript over the public HTTP API.
//
// - The texture list polls `/v1/textures` and shows each texture's name
//   (the uploaded file's) and a thumbnail of its exemplar; an exemplar
//   dropped on the page is uploaded as a form (the file name labels it)
//   with the API's default parameters, or the few set under "advanced".
// - Slice and cut views are tiled: TILE² pixel tiles at the level of detail
//   that matches the screen's pixel size, addressed by (plane, lod, tile),
//   kept decoded in an LRU and drawn at once when cached. While the tiles of
//   that level arrive, coarser cached tiles are drawn scaled up; tiles that
//   scroll away are cancelled, a few requests run at once, and 503 answers
//   are retried after `Retry-After`. The canvas says `data-complete="1"`
//   once every visible tile of the target level (`data-lod`) is drawn.
//   A smoothly magnified level is laid out whole before it is scaled, so
//   tiles meet without seams; another cut angle or axis holds the last
//   whole frame until the new plane is covered; a whole view keeps a
//   coarse backdrop around it so that zooming out shows no background.
// - The address holds the view (texture, mode, axis, position, centre,
//   zoom, cut angles), so that a place can be bookmarked; editing it in
//   an open tab moves there.
// - The 3D preview fetches one brick as raw RGB8 into a WebGL2 3D texture
//   and ray-casts a carved shape (cube or sphere, cut by a plane) through
//   it, so every face shows the solid texture; the finest level, with the
//   same block at a coarse level shown while it loads.
// - The mesh view bakes a model (the shipped torus, or an OBJ or GLB the
//   user drops) through the bake route, draws it lit with a bump from the
//   texture's luminance, and clips it by a plane whose cap is the cut
//   route's image of the solid on that plane (stencil parity marks where
//   the plane lies inside the model).
// - The field panel gives the selected texture a field of local frames (a
//   preset, or curves clicked on the slice) by asking for a variant of it,
//   which shares its candidates, and switches to that texture; arrows of
//   the local x axis, sampled by the frames route, can be drawn over the
//   slice, with the curves being drawn.
"use strict";

const API = "/v1/textures";
const $ = (id) => document.getElementById(id);

// Coordinates are integers within ±2^31 (openapi `Coordinate`).
const COORD_MIN = -2147483648;
const COORD_MAX = 2147483647;
const TILE = 128; // tile side in pixels of its level of detail
const MAX_INFLIGHT = 4; // tile requests at once, at most (fewer after a 503)
const CACHE_TILES = 640; // decoded tiles kept (64 KiB each)
const MAX_SCALE = 32; // screen pixels per finest voxel, zoomed in
const LOD_SLACK = 0.15; // see targetLod

const state = {
  textures: [],
  selected: null, // texture view (JSON) of the selected texture
  mode: "slice",
  axis: "z",
  position: 0, // slice position / cut offset, finest voxels
  center: [0, 0], // view centre in plane coordinates, finest voxels
  scale: 2, // CSS pixels per finest voxel
  yaw: 30,
  pitch: 35,
  shape: "sphere",
  carve: 0.1,
  blockLod: null,
  meshCut: 0.15, // the mesh view's plane, -1 … 1 across the model (1: whole)
  orbit: { yaw: -35, pitch: 25, distance: 3.6 },
  uploading: null, // id of a texture being precomputed after an upload
  progressive: true, // coarse tiles first while the target level arrives
  field: {
    curves: [], // sketched curves: { points: [[x, y, z], …], normal, axis, at }
    current: -1, // index of the curve clicks extend (-1: start a new one)
    drawing: false, // clicks on the slice add points
    arrows: false, // local x arrows over the slice
  },
};

/// Whether the view is a plane of tiles (slice or cut).
const planar = () => state.mode === "slice" || state.mode === "cut";

const clampCoord = (v) => Math.max(COORD_MIN, Math.min(COORD_MAX, v));

/// A texture's label: the uploaded file's name, else a short id; then
/// its field, and its seed when another listed texture would read the same
/// (variants keep their base's name).
function label(t) {
  if (!t) return "";
  const base = (x) => {
    const name = x.name || (x.id.length > 12 ? x.id.slice(0, 8) + "…" : x.id);
    const f = x.params && x.params.field;
    return f ? `${name} · ${describeField(f)}` : name;
  };
  const text = base(t);
  const twin = state.textures.some((x) => x.id !== t.id && base(x) === text);
  return twin && t.params && t.params.seed != null ? `${text} · seed ${t.params.seed}` : text;
}

/// How a field reads in a sentence.
function describeField(f) {
  if (!f) return "no field";
  if (f.kind === "slant") return `slant ${f.angle}°`;
  if (f.kind === "zigzag") return `zigzag ±${f.angle}° every ${f.period}`;
  if (f.kind === "sketch") return `${f.curves.length} drawn curve${f.curves.length > 1 ? "s" : ""}`;
  if (f.kind === "slant3d") return `3D slant towards ${f.direction.join(", ")}`;
  if (f.centre) return `${f.kind} about ${f.centre.join(", ")}`;
  return f.kind;
}

/// The grain the analysis detected on the exemplar, in words, or null.
function describeGrain(t) {
  const o = t && t.orientation;
  if (!o || o.grain_degrees == null) return null;
  const deg = Math.round(o.grain_degrees);
  const strength = o.coherence >= 0.6 ? "strong" : o.coherence >= 0.3 ? "weak" : "none to speak of";
  return `grain ${deg}° from u (coherence ${o.coherence.toFixed(2)}, ${strength})` +
    (o.detected ? "; planes arranged along it" : "");
}

/// Device pixels per CSS pixel, capped: the level of detail follows the
/// screen's own pixels.
function dpr() {
  return Math.max(1, Math.min(2, window.devicePixelRatio || 1));
}

/// The smallest zoom: one coarsest-level voxel per device pixel.
function minScale() {
  const t = state.selected;
  const maxLod = t && t.max_lod != null ? t.max_lod : 3;
  return 2 ** -maxLod / dpr();
}

// ---------------------------------------------------------------------
// Status line

// Sizes a canvas to its box in device pixels; returns [width, height].
function fitCanvas(canvas) {
  const r = canvas.getBoundingClientRect();
  const d = dpr();
  const w = Math.max(1, Math.round(r.width * d)), h = Math.max(1, Math.round(r.height * d));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
  return [w, h];
}

// Runs a view's WebGL set-up (`setup` returns whether WebGL2 is there);
// says why the view is off when it fails.
function webglReady(setup, view) {
  try {
    if (setup()) return true;
    say(`WebGL2 is not available in this browser: ${view} is off`, true);
  } catch (e) {
    say(`WebGL setup failed: ${e.message}`, true);
  }
  return false;
}

function say(text, isError) {
  const s = $("status");
  s.textContent = text;
  s.classList.toggle("error", !!isError);
}

/// The message of a JSON error answer (`{"error": {code, message}}`).
async function errorText(res) {
  try {
    const v = await res.json();
    return v.error ? `${v.error.message} (${v.error.code})` : `${res.status} ${res.statusText}`;
  } catch (_) {
    return `${res.status} ${res.statusText}`;
  }
}

// ---------------------------------------------------------------------
// Texture list, selected texture and upload

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
  const changed = JSON.stringify(v.textures) !== JSON.stringify(state.textures);
  state.textures = v.textures;
  if (changed) renderList();
  if (state.selected) {
    const now = state.textures.find((t) => t.id === state.selected.id);
    if (!now) {
      select(state.textures.find((t) => t.status === "ready") || null);
    } else if (now.status !== state.selected.status || now.name !== state.selected.name) {
      select(now);
    }
  } else {
    const linked = linkedView && state.textures.find((t) => t.id === linkedView.t);
    if (linkedView && !linked) linkedView = null; // a texture that is gone
    const first = linked || state.textures.find((t) => t.status === "ready");
    if (first) select(first);
  }
  if (state.uploading) {
    const t = state.textures.find((t) => t.id === state.uploading);
    if (t && t.status === "ready") {
      say(`${label(t)} is ready (${(t.precompute_seconds || 0).toFixed(1)} s)`);
      state.uploading = null;
      select(t);
    } else if (t && t.status === "failed") {
      say(`precompute of ${label(t)} failed: ${t.reason}`, true);
      state.uploading = null;
    } else if (t) {
      say(`precomputing ${label(t)}: ${t.stage} ${(t.progress * 100).toFixed(0)}%`);
    }
  }
}

const listItems = new Map(); // id -> li, reused so that focus and thumbnails stay

function listItem(t) {
  let li = listItems.get(t.id);
  if (li) return li;
  li = document.createElement("li");
  li.tabIndex = 0;
  li.dataset.id = t.id;
  // The thumbnail route and the name arrived together in the API.
  if ("name" in t) {
    const img = document.createElement("img");
    img.className = "thumb";
    img.alt = "";
    img.decoding = "async";
    img.src = `${API}/${encodeURIComponent(t.id)}/exemplar.png`;
    img.addEventListener("error", () => { img.style.visibility = "hidden"; });
    li.append(img);
  } else {
    const ph = document.createElement("div");
    ph.className = "thumb";
    li.append(ph);
  }
  const text = document.createElement("div");
  text.className = "text";
  const name = document.createElement("div");
  name.className = "name";
  const meta = document.createElement("div");
  meta.className = "meta";
  const bar = document.createElement("div");
  bar.className = "bar";
  bar.append(document.createElement("div"));
  text.append(name, meta, bar);
  li.append(text);
  const pick = () => {
    const now = state.textures.find((x) => x.id === t.id);
    if (now) select(now);
  };
  li.addEventListener("click", pick);
  li.addEventListener("keydown", (e) => {
    if (e.key === "Enter" || e.key === " ") {
      e.preventDefault();
      pick();
    }
  });
  listItems.set(t.id, li);
  return li;
}

function renderList() {
  const ul = $("textures");
  const ids = new Set(state.textures.map((t) => t.id));
  for (const [id, li] of listItems) {
    if (!ids.has(id)) {
      li.remove();
      listItems.delete(id);
    }
  }
  let prev = null;
  for (const t of state.textures) {
    const li = listItem(t);
    li.dataset.status = t.status;
    li.classList.toggle("selected", !!(state.selected && state.selected.id === t.id));
    const [, text] = li.children;
    const [name, meta, bar] = text.children;
    name.textContent = label(t);
    const size = `${t.exemplar.width}×${t.exemplar.height}`;
    const field = t.params && t.params.field ? ` · ${t.params.field.kind || "field"}` : "";
    meta.textContent =
      t.status === "ready" ? `${size} · seed ${t.params && t.params.seed != null ? t.params.seed : "?"}${field} · ${t.id.slice(0, 8)}`
        : t.status === "failed" ? `${size} · failed`
          : `${size} · ${t.stage} ${(t.progress * 100).toFixed(0)}%`;
    bar.hidden = t.status !== "pending";
    bar.firstChild.style.width = `${(t.progress * 100).toFixed(1)}%`;
    li.title = t.status === "failed" ? `${label(t)}: ${t.reason}` : `${label(t)}\n${t.id}`;
    const want = prev ? prev.nextSibling : ul.firstChild;
    if (want !== li) ul.insertBefore(li, want);
    prev = li;
  }
}

// The parameters a user is likely to care about come first.
const PARAM_ORDER = ["seed", "feature_weight", "passes", "finest_passes", "fine_levels", "parity_levels", "levels", "neighbourhood", "scheme", "grid", "jitter", "contrast", "consistency", "slices", "slab_thickness"];

function renderInfo() {
  const box = $("info");
  const t = state.selected;
  const wasOpen = !!(box.querySelector("#params") || {}).open;
  box.hidden = !t;
  box.textContent = "";
  if (!t) return;
  const head = document.createElement("div");
  head.innerHTML = `<strong></strong><div class="id"></div><div class="what"></div>`;
  head.querySelector("strong").textContent = label(t);
  head.querySelector(".id").textContent = t.id;
  const bits = [`${t.exemplar.width}×${t.exemplar.height} exemplar`, t.exemplar.planes === 3 ? "3 planes" : "1 plane"];
  if (t.status === "ready") bits.push(`lod 0–${t.max_lod}`, `brick ${t.brick_size}³`);
  else bits.push(t.status);
  if (t.precompute_seconds != null) bits.push(`precomputed in ${t.precompute_seconds.toFixed(1)} s`);
  head.querySelector(".what").textContent = bits.join(" · ");
  const grain = describeGrain(t);
  if (grain) {
    const g = document.createElement("div");
    g.className = "grain";
    g.textContent = grain;
    g.title = "Measured on the exemplar's luminance by the structure tensor: the direction the stripes run, in degrees from the image's u axis towards v";
    head.append(g);
  }
  const det = document.createElement("details");
  det.id = "params";
  det.open = wasOpen;
  const sum = document.createElement("summary");
  sum.textContent = "parameters";
  const table = document.createElement("table");
  const keys = Object.keys(t.params || {}).sort((a, b) => {
    const ia = PARAM_ORDER.indexOf(a), ib = PARAM_ORDER.indexOf(b);
    return (ia < 0 ? 99 : ia) - (ib < 0 ? 99 : ib) || a.localeCompare(b);
  });
  for (const k of keys) {
    const tr = document.createElement("tr");
    const a = document.createElement("td"), b = document.createElement("td");
    a.textContent = k;
    const value = t.params[k];
    b.textContent = value && typeof value === "object" ? JSON.stringify(value) : String(value);
    tr.append(a, b);
    table.append(tr);
  }
  det.append(sum, table);
  const actions = document.createElement("div");
  actions.className = "actions";
  const del = document.createElement("button");
  del.className = "btn danger";
  del.id = "delete";
  del.textContent = "Delete";
  del.title = "Delete this texture and its stored files";
  del.addEventListener("click", () => remove(t));
  actions.append(del);
  box.append(head, det, actions);
}

/// The selected texture's exemplar beside the view, to compare with.
function renderInset() {
  const fig = $("inset");
  const t = state.selected;
  // The exemplar route arrived with texture names in the API.
  if (!t || !("name" in t)) {
    fig.hidden = true;
    return;
  }
  const img = fig.querySelector("img");
  const src = `${API}/${encodeURIComponent(t.id)}/exemplar.png`;
  if (img.getAttribute("src") !== src) {
    fig.hidden = true;
    img.onload = () => { fig.hidden = false; };
    img.onerror = () => { fig.hidden = true; };
    img.src = src;
  }
  fig.querySelector("figcaption").textContent = `exemplar ${t.exemplar.width}×${t.exemplar.height}`;
  // The detected grain as a line across the exemplar (v points down).
  const line = fig.querySelector(".grain");
  const o = t.orientation;
  line.hidden = !o || o.grain_degrees == null || !(o.coherence >= 0.3);
  if (!line.hidden) {
    line.style.transform = `translate(-50%, -50%) rotate(${o.grain_degrees}deg)`;
    line.title = describeGrain(t);
  }
}

function select(t) {
  const changed = !state.selected || !t || state.selected.id !== t.id;
  if (linkedView && (!t || t.id !== linkedView.t)) linkedView = null;
  state.selected = t;
  renderList();
  renderInfo();
  renderInset();
  fieldUi.selected();
  if (!t || t.status !== "ready") {
    plane.clear(t ? `${label(t)}: ${t.status}` : "no texture: drop an exemplar on the left");
    solid.clear();
    updateDownloads();
    return;
  }
  const lodSel = $("block-lod");
  if (changed || lodSel.options.length !== t.max_lod + 1) {
    lodSel.textContent = "";
    for (let k = t.max_lod; k >= 0; k--) {
      const o = document.createElement("option");
      o.value = String(k);
      o.textContent = k === 0 ? "lod 0 (finest)" : `lod ${k}`;
      lodSel.append(o);
    }
    // The finest level: coarse levels lose the exemplar's small features
    // (wood's grain), and the preview shows the coarsest first anyway.
    state.blockLod = 0;
    lodSel.value = "0";
  }
  state.scale = Math.max(minScale(), state.scale);
  if (linkedView) applyLinkedView();
  plane.invalidate(true);
  solid.invalidate();
  meshView.bake();
}

async function remove(t) {
  if (!window.confirm(`Delete texture “${label(t)}” (${t.id})? Its stored files are removed.`)) return;
  let res;
  try {
    res = await fetch(`${API}/${encodeURIComponent(t.id)}`, { method: "DELETE" });
  } catch (e) {
    say(`delete failed: ${e.message}`, true);
    return;
  }
  if (!res.ok) {
    say(`could not delete ${label(t)}: ${await errorText(res)}`, true);
    return;
  }
  say(`deleted ${label(t)}`);
  if (state.selected && state.selected.id === t.id) state.selected = null;
  await refreshList();
  if (!state.selected) select(null);
}

/// The advanced upload parameters that are set, as a JSON object.
function uploadParams() {
  const p = {};
  const seed = $("p-seed").value.trim();
  if (seed !== "") p.seed = Number(seed);
  if ($("p-preset").value) p.preset = $("p-preset").value;
  const feature = $("p-feature-weight").value.trim();
  if (feature !== "") p.feature_weight = Number(feature);
  const passes = $("p-passes").value.trim();
  if (passes !== "") p.passes = Number(passes);
  return p;
}

async function upload(file) {
  if (!file) return;
  if (file.type && file.type !== "image/png" && file.type !== "image/jpeg") {
    say(`${file.name}: only PNG and JPEG exemplars are accepted`, true);
    return;
  }
  const params = uploadParams();
  if (params.seed != null && !(Number.isInteger(params.seed) && params.seed >= 0)) {
    say("the seed must be a whole number ≥ 0", true);
    return;
  }
  // A form carries the file's name, which labels the texture; parameters
  // left unset keep the API's defaults, so the same image is the same id
  // whatever client uploads it.
  const form = new FormData();
  form.append("image", file, file.name || "exemplar.png");
  const mask = $("p-feature-mask").files[0];
  if (mask) {
    if (!(params.feature_weight > 0)) {
      say("a feature mask needs a feature weight above 0", true);
      return;
    }
    form.append("feature_mask", mask, mask.name || "mask.png");
  }
  if (Object.keys(params).length) form.append("params", JSON.stringify(params));
  say(`uploading ${file.name}…`);
  let res;
  try {
    res = await fetch(API, { method: "POST", body: form });
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
  const notes = t.notes && t.notes.length ? ` (${t.notes.join("; ")})` : "";
  say((t.status === "ready" ? `${label(t)} is known already` : `precomputing ${label(t)}…`) + notes);
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
  input.addEventListener("change", () => {
    upload(input.files[0]);
    input.value = "";
  });
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
// Downloads: the view as PNG, and a raw brick around the view centre

const BRICK = 64;

/// The finest-voxel position of the view centre.
function centreVoxel() {
  const c = { x: 0, y: 0, z: 0 };
  if (state.mode === "cut") {
    const { u, v, n } = cutBasis();
    ["x", "y", "z"].forEach((a, i) => {
      c[a] = Math.floor(n[i] * state.position + u[i] * state.center[0] + v[i] * state.center[1]);
    });
    return c;
  }
  const frame = { z: ["x", "y"], x: ["y", "z"], y: ["z", "x"] }[state.axis];
  c[frame[0]] = Math.floor(state.center[0]);
  c[frame[1]] = Math.floor(state.center[1]);
  c[state.axis] = state.position;
  return c;
}

// ---------------------------------------------------------------------
// The view in the address (#t=ID&m=slice&a=z&p=0&c=0,0&s=2&yaw=30&pitch=35),
// so that a place in the infinite texture can be bookmarked and shared.

function viewInAddress() {
  const q = new URLSearchParams(location.hash.slice(1));
  return q.has("t") ? Object.fromEntries(q) : null;
}
let linkedView = viewInAddress();

/// An address edited in an open tab (or Back and Forward between views)
/// moves the view there, selecting its texture when it is another.
function followAddress() {
  const q = viewInAddress();
  if (!q || location.hash === lastLink) return;
  const t = state.textures.find((x) => x.id === q.t);
  if (!t) {
    say(`the address names a texture this server does not list: ${q.t}`, true);
    return;
  }
  linkedView = q;
  if (state.selected && state.selected.id === t.id && t.status === "ready") {
    const mode = state.mode;
    applyLinkedView();
    if (state.mode === mode) {
      if (mode === "solid") solid.invalidate();
      else if (mode === "mesh") meshView.bake();
      else plane.invalidate(true);
    }
    updateDownloads();
  } else {
    select(t);
  }
}

/// Applies the view named in the address, once its texture is selected.
function applyLinkedView() {
  const q = linkedView;
  linkedView = null;
  if (!q || !state.selected || q.t !== state.selected.id) return;
  const num = (x, d) => (x != null && x !== "" && Number.isFinite(Number(x)) ? Number(x) : d);
  if (["x", "y", "z"].includes(q.a)) {
    state.axis = q.a;
    $("axis").value = q.a;
  }
  const c = (q.c || "").split(",").map(Number);
  if (c.length === 2 && c.every(Number.isFinite)) state.center = c.map(clampCoord);
  state.scale = Math.max(minScale(), Math.min(MAX_SCALE, num(q.s, state.scale)));
  for (const k of ["yaw", "pitch"]) {
    const lim = k === "yaw" ? 180 : 90;
    state[k] = Math.max(-lim, Math.min(lim, Math.round(num(q[k], state[k]))));
    $(k).value = String(state[k]);
    $(`${k}-out`).textContent = String(state[k]);
  }
  setPosition(num(q.p, state.position));
  if (["slice", "cut", "solid", "mesh"].includes(q.m) && q.m !== state.mode) setMode(q.m);
}

let linkTimer = null;
let lastLink = location.hash; // the address as the viewer last wrote it
function updateLink() {
  clearTimeout(linkTimer);
  linkTimer = setTimeout(() => {
    const t = state.selected;
    if (!t || linkedView) return;
    const c = state.center.map((x) => Math.round(x)).join(",");
    const q = `t=${encodeURIComponent(t.id)}&m=${state.mode}&a=${state.axis}&p=${state.position}&c=${c}` +
      `&s=${+state.scale.toPrecision(4)}&yaw=${state.yaw}&pitch=${state.pitch}`;
    if (location.hash !== `#${q}`) history.replaceState(null, "", `#${q}`);
    lastLink = location.hash;
  }, 400);
}

function updateDownloads() {
  updateLink();
  const a = $("download-raw");
  const t = state.selected;
  if (!t || t.status !== "ready") {
    a.setAttribute("aria-disabled", "true");
    a.removeAttribute("href");
    return;
  }
  const lod = state.mode === "solid" ? (state.blockLod ?? t.max_lod) : plane.targetLod();
  const k = 2 ** lod;
  const c = centreVoxel();
  const o = ["x", "y", "z"].map((ax) => Math.max(COORD_MIN, Math.min(COORD_MAX - BRICK, Math.floor(c[ax] / k) - BRICK / 2)));
  a.href = `${API}/${encodeURIComponent(t.id)}/region.raw?x=${o[0]}&y=${o[1]}&z=${o[2]}&w=${BRICK}&h=${BRICK}&d=${BRICK}&lod=${lod}`;
  const base = (t.name || t.id).replace(/\.[A-Za-z0-9]+$/, "").replace(/[^A-Za-z0-9_.-]+/g, "_");
  a.download = `${base}-${o.join("_")}-lod${lod}-${BRICK}x${BRICK}x${BRICK}.rgb8.raw`;
  a.removeAttribute("aria-disabled");
  a.title =
    `${BRICK}³ voxels at lod ${lod} (voxels ${k} finest voxel${k > 1 ? "s" : ""} wide) around the view centre, ` +
    `lowest corner ${o.join(", ")} in lod-${lod} voxels.\n` +
    `Raw RGB8: ${BRICK ** 3 * 3} bytes, 3 per voxel (r, g, b); x varies fastest, then y, then z: ` +
    `byte 3·(x + ${BRICK}·(y + ${BRICK}·z)) is voxel (x, y, z)'s red. ` +
    "The X-Solidtex-* headers repeat the shape and origin.";
}

function setupDownloads() {
  $("download-png").addEventListener("click", (e) => {
    const canvas = state.mode === "solid" ? $("solid") : state.mode === "mesh" ? $("mesh") : $("plane");
    const a = $("download-png");
    if (a.dataset.ready === "1") {
      a.dataset.ready = "0";
      return; // the link holds this view's PNG: let the browser save it
    }
    e.preventDefault();
    const t = state.selected;
    const where = state.mode === "slice" ? `${state.axis}${state.position}` : state.mode === "cut" ? `cut${state.yaw}_${state.pitch}_${state.position}` : "3d";
    canvas.toBlob((blob) => {
      if (!blob) return;
      if (a.href.startsWith("blob:")) URL.revokeObjectURL(a.href);
      a.href = URL.createObjectURL(blob);
      a.download = `${t ? (t.name || t.id).replace(/\.[A-Za-z0-9]+$/, "") : "solidtex"}-${where}.png`;
      a.dataset.ready = "1";
      a.click();
    }, "image/png");
  });
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
  const ctx = canvas.getContext("2d", { alpha: false });
  // Tile key -> { bmp, r }: the decoded part r = [x0, y0, x1, y1] (tile
  // pixels) of the tile, least recently used first. A tile at the edge of
  // the view is asked for only as far as it shows (in SNAP steps) and
  // grown when more of it comes into view.
  const cache = new Map();
  const inflight = new Map(); // tile key -> { ctrl, r }
  const retryAt = new Map(); // tile key -> time before which not to ask again
  const failed = new Map(); // tile key -> message, not asked again
  let queue = []; // tiles to fetch, most wanted first
  let snapshot = null; // the last complete frame, drawn under missing tiles
  let drawQueued = false;
  let fetchTimer = null;
  let retryTimer = null;
  let hudText = "";
  let errorShown = false;
  // Requests at once: halved on each 503 (the server's queue is full or
  // too slow), grown back as tiles arrive.
  let limit = MAX_INFLIGHT;
  canvas.dataset.drawn = "0";
  canvas.dataset.complete = "0";

  // Canvas size in device pixels, following its box.
  function size() {
    return fitCanvas(canvas);
  }

  /// The level of detail whose voxels match the screen's pixels: the
  /// coarsest whose voxel is no wider than a device pixel, give or take
  /// LOD_SLACK (2^0.15: at most 11 % magnified, which does not show, where
  /// the next finer level would cost up to 4 times the pixels: 0.27
  /// px/voxel is lod 2, not 1).
  function targetLod() {
    const t = state.selected;
    if (!t || t.max_lod == null) return 0;
    const voxelsPerPixel = 1 / (state.scale * dpr());
    const lod = Math.floor(Math.log2(voxelsPerPixel) + LOD_SLACK + 1e-9);
    return Math.max(0, Math.min(t.max_lod, lod));
  }

  /// What the canvas shows now: the plane, where, and at which scale.
  function currentView() {
    const t = state.selected;
    if (!t || t.status !== "ready" || !planar()) return null;
    const [W, H] = size();
    const ps = state.scale * dpr(); // device pixels per finest voxel
    const v = {
      t, W, H, ps, mode: state.mode,
      cx: state.center[0], cy: state.center[1],
      target: targetLod(),
    };
    const id = encodeURIComponent(t.id), pos = state.position;
    if (state.mode === "slice") {
      const axis = state.axis;
      v.plane = `${t.id}|s|${axis}`;
      v.source = (lod) => `${v.plane}|${Math.floor(pos / 2 ** lod)}`;
      v.url = (lod, i, j, r) =>
        `${API}/${id}/slices/${axis}/${Math.floor(pos / 2 ** lod)}.png?u0=${i * TILE + r[0]}&v0=${j * TILE + r[1]}` +
        `&w=${r[2] - r[0]}&h=${r[3] - r[1]}&lod=${lod}`;
    } else {
      const { u, v: vv, n } = cutBasis();
      const yaw = state.yaw, pitch = state.pitch;
      // Trilinear samples where a voxel spans screen pixels; otherwise the
      // nearest voxel, which depends on a thinner sheet of voxels (a cold
      // cut costs about a quarter less) and looks the same there.
      const filter = 2 ** v.target * ps >= 1.5 ? "trilinear" : "nearest";
      // Another angle is another plane: its old frame is held whole until
      // the new one covers the view, never drawn under the new tiles.
      v.plane = `${t.id}|c|${yaw}|${pitch}`;
      v.source = () => `${v.plane}|${yaw}|${pitch}|${pos}|${filter}`;
      const f = (a) => a.map((x) => (Math.abs(x) < 5e-7 ? 0 : x).toFixed(6)).join(",");
      // Pixel (x, y) of tile (i, j) at lod l is n·pos + u·(i·T + x)·2^l +
      // v·(j·T + y)·2^l finest voxels: a pixel steps one lod-l voxel.
      v.url = (lod, i, j, r) => {
        const k = 2 ** lod, a = i * TILE + r[0], b = j * TILE + r[1];
        const o = [0, 1, 2].map((c) => (n[c] * pos) / k + u[c] * a + vv[c] * b);
        return `${API}/${id}/cut.png?origin=${f(o)}&u=${f(u)}&v=${f(vv)}&w=${r[2] - r[0]}&h=${r[3] - r[1]}` +
          `&lod=${lod}&filter=${filter}`;
      };
    }
    return v;
  }

  const SNAP = 32; // tile parts are asked for in steps of SNAP pixels

  /// The tiles of `lod` that the view `v` shows, nearest the centre first,
  /// each with the part `need` of it that shows.
  function tiles(v, lod, grow = 1) {
    const k = 2 ** lod, span = TILE * k;
    // The view (grown `grow` times about its centre) in lod-l pixels.
    const hw = (grow * v.W) / 2 / v.ps, hh = (grow * v.H) / 2 / v.ps;
    const x0 = (v.cx - hw) / k, x1 = (v.cx + hw) / k;
    const y0 = (v.cy - hh) / k, y1 = (v.cy + hh) / k;
    const i0 = Math.floor(x0 / TILE), i1 = Math.ceil(x1 / TILE) - 1;
    const j0 = Math.floor(y0 / TILE), j1 = Math.ceil(y1 / TILE) - 1;
    const src = v.source(lod);
    const out = [];
    // Tiles past the coordinate range are left out (nothing to show).
    const lim = (i) => i * TILE >= COORD_MIN && (i + 1) * TILE - 1 <= COORD_MAX;
    const part = (lo, hi, i) => [
      Math.max(0, Math.floor((lo - i * TILE) / SNAP) * SNAP),
      Math.min(TILE, Math.ceil((hi - i * TILE) / SNAP) * SNAP),
    ];
    for (let j = j0; j <= j1; j++) {
      for (let i = i0; i <= i1; i++) {
        if (!lim(i) || !lim(j)) continue;
        const [nx0, nx1] = part(x0, x1, i), [ny0, ny1] = part(y0, y1, j);
        if (nx1 <= nx0 || ny1 <= ny0) continue;
        const mx = (i + 0.5) * span - v.cx, my = (j + 0.5) * span - v.cy;
        out.push({ lod, i, j, k, key: `${src}|${lod}|${i}|${j}`, d: mx * mx + my * my, need: [nx0, ny0, nx1, ny1] });
      }
    }
    out.sort((a, b) => a.d - b.d);
    return out;
  }

  const covers = (r, need) => r[0] <= need[0] && r[1] <= need[1] && r[2] >= need[2] && r[3] >= need[3];
  const union = (a, b) => [Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.max(a[2], b[2]), Math.max(a[3], b[3])];

  /// Whether the part of `tile` that shows is cached (or will never be).
  function have(tile) {
    const e = cache.get(tile.key);
    return (e && covers(e.r, tile.need)) || failed.has(tile.key);
  }

  function touch(key) {
    const e = cache.get(key);
    if (e) {
      cache.delete(key);
      cache.set(key, e);
    }
    return e;
  }

  function put(key, bmp, r) {
    const old = cache.get(key);
    if (old && old.bmp.close) old.bmp.close();
    cache.delete(key);
    cache.set(key, { bmp, r });
    while (cache.size > CACHE_TILES) {
      const [k, e] = cache.entries().next().value;
      cache.delete(k);
      if (e.bmp.close) e.bmp.close();
    }
  }

  function drawTile(v, tile, e) {
    const s = tile.k * v.ps; // device pixels per tile pixel
    const ox = (tile.i * TILE * tile.k - v.cx) * v.ps + v.W / 2;
    const oy = (tile.j * TILE * tile.k - v.cy) * v.ps + v.H / 2;
    // Rounded edges, so that neighbours meet without seams.
    const sx0 = Math.round(ox + e.r[0] * s), sx1 = Math.round(ox + e.r[2] * s);
    const sy0 = Math.round(oy + e.r[1] * s), sy1 = Math.round(oy + e.r[3] * s);
    ctx.drawImage(e.bmp, sx0, sy0, sx1 - sx0, sy1 - sy0);
  }

  // A level magnified smoothly is laid out whole at its own pixels first
  // and scaled once: each tile scaled on its own would be smoothed against
  // its own clamped edge, a cross of seams where tiles meet.
  const mosaic = document.createElement("canvas");
  const mosaicCtx = mosaic.getContext("2d");
  function drawMosaic(v, list) {
    const k = 2 ** v.target, s = k * v.ps;
    const x0 = Math.floor((v.cx - v.W / 2 / v.ps) / k) - 1, x1 = Math.ceil((v.cx + v.W / 2 / v.ps) / k) + 1;
    const y0 = Math.floor((v.cy - v.H / 2 / v.ps) / k) - 1, y1 = Math.ceil((v.cy + v.H / 2 / v.ps) / k) + 1;
    const w = x1 - x0, h = y1 - y0;
    if (mosaic.width !== w || mosaic.height !== h) {
      mosaic.width = w;
      mosaic.height = h;
    } else {
      mosaicCtx.clearRect(0, 0, w, h);
    }
    for (const tile of list) {
      const e = touch(tile.key);
      if (e) mosaicCtx.drawImage(e.bmp, tile.i * TILE + e.r[0] - x0, tile.j * TILE + e.r[1] - y0);
    }
    ctx.imageSmoothingEnabled = true;
    ctx.drawImage(mosaic, (x0 * k - v.cx) * v.ps + v.W / 2, (y0 * k - v.cy) * v.ps + v.H / 2, w * s, h * s);
  }

  function requestDraw() {
    if (drawQueued) return;
    drawQueued = true;
    requestAnimationFrame(() => {
      drawQueued = false;
      draw();
    });
  }

  // Draws what is cached: the last complete frame, coarser levels scaled
  // up, then the target level; updates progress and the HUD.
  function draw() {
    const v = currentView();
    const [W, H] = size();
    ctx.fillStyle = "#0d0e10";
    ctx.fillRect(0, 0, W, H);
    if (!v) return;
    const want = tiles(v, v.target);
    const done = want.filter(have).length;
    const complete = done === want.length;
    // Whether some level covers the whole view already (coarse at first).
    let covered = complete;
    for (let lod = v.target + 1; lod <= v.t.max_lod && !covered; lod++) covered = tiles(v, lod).every(have);
    // The last complete frame of another plane of this texture (another
    // cut angle, axis or view) stays whole until the new one covers the
    // view: half of one against half of the other reads as neither.
    const held = !covered && snapshot && snapshot.plane !== v.plane && snapshot.tid === v.t.id;
    canvas.dataset.held = held ? "1" : "0";
    if (!complete) {
      if (snapshot && (snapshot.plane === v.plane || held)) {
        // The last complete frame, where it lies in this one.
        const s = snapshot, f = v.ps / s.ps;
        ctx.imageSmoothingEnabled = true;
        ctx.drawImage(s.canvas, (s.cx - s.W / 2 / s.ps - v.cx) * v.ps + W / 2, (s.cy - s.H / 2 / s.ps - v.cy) * v.ps + H / 2, s.W * f, s.H * f);
      }
    }
    if (held) {
      canvas.dataset.lod = String(v.target);
      canvas.dataset.tiles = `${done}/${want.length}`;
      canvas.dataset.complete = "0";
      canvas.dataset.covered = "0";
      $("progress").firstChild.style.width = `${(100 * Math.max(done, 0.3)) / want.length}%`;
      hud(v, done, want.length);
      fieldUi.draw(v);
      return;
    }
    if (!complete) {
      // Coarser levels scaled up (smoothly), then a finer level cached
      // from before a zoom-out.
      ctx.imageSmoothingEnabled = true;
      for (let lod = v.t.max_lod; lod > v.target; lod--) {
        for (const tile of tiles(v, lod)) {
          const e = touch(tile.key);
          if (e) drawTile(v, tile, e);
        }
      }
      if (v.target > 0) {
        const finer = tiles(v, v.target - 1);
        if (finer.length <= 400) {
          for (const tile of finer) {
            const e = cache.get(tile.key);
            if (e) drawTile(v, tile, e);
          }
        }
      }
    }
    // The target level: crisp voxels when magnified twice or more, except
    // in cuts, whose pixels are trilinear samples of the plane.
    const smooth = v.mode === "cut" || 2 ** v.target * v.ps < 2;
    if (smooth && 2 ** v.target * v.ps > 1.01) {
      drawMosaic(v, want);
    } else {
      ctx.imageSmoothingEnabled = smooth;
      for (const tile of want) {
        const e = touch(tile.key);
        if (e) drawTile(v, tile, e);
      }
    }
    canvas.dataset.lod = String(v.target);
    canvas.dataset.tiles = `${done}/${want.length}`;
    canvas.dataset.complete = complete ? "1" : "0";
    canvas.dataset.covered = covered ? "1" : "0";
    $("progress").firstChild.style.width = complete ? "0" : `${(100 * Math.max(done, 0.3)) / want.length}%`;
    if (complete) {
      // Kept to stand in for missing tiles after the next move.
      if (!snapshot || snapshot.canvas.width !== W || snapshot.canvas.height !== H) {
        const c = document.createElement("canvas");
        c.width = W;
        c.height = H;
        snapshot = { canvas: c };
      }
      snapshot.canvas.getContext("2d").drawImage(canvas, 0, 0);
      Object.assign(snapshot, { plane: v.plane, tid: v.t.id, cx: v.cx, cy: v.cy, ps: v.ps, W, H });
    }
    hud(v, done, want.length);
    fieldUi.draw(v);
  }

  function hud(v, done, total) {
    const where = v.mode === "slice" ? `${state.axis} = ${state.position}` : `yaw ${state.yaw}° pitch ${state.pitch}° offset ${state.position}`;
    const zoom = state.scale >= 1 ? `${+state.scale.toFixed(2)} px/voxel` : `${+state.scale.toFixed(3)} px/voxel (${+(1 / state.scale).toFixed(2)} voxels/px)`;
    const progress = done === total ? `${total} tiles` : `${done} / ${total} tiles`;
    const text = `${label(v.t)} · ${where} · centre ${state.center.map((c) => c.toFixed(0)).join(", ")}\n${zoom} · lod ${v.target} · ${progress}`;
    if (text !== hudText) {
      $("hud").textContent = text;
      hudText = text;
    }
  }

  // Chooses the tiles to fetch for the current view: a coarse level first
  // when nothing coarse covers the view yet, then the target level from
  // the centre out. Requests for tiles no longer shown are cancelled.
  function schedule() {
    clearTimeout(fetchTimer);
    fetchTimer = null;
    const v = currentView();
    const wanted = [];
    if (v) {
      const want = tiles(v, v.target).filter((x) => !have(x));
      if (want.length) {
        const coarse = Math.min(v.t.max_lod, v.target + 2);
        let covered = false;
        for (let lod = coarse; lod > v.target && !covered; lod--) covered = tiles(v, lod).every(have);
        if (state.progressive && coarse > v.target && !covered) wanted.push(...tiles(v, coarse).filter((x) => !have(x)));
        wanted.push(...want);
      } else if (state.progressive) {
        // The view is whole: a coarse backdrop twice its size, so that a
        // zoom out (or a pan) shows a coarser level scaled up at once
        // rather than background while its own tiles arrive.
        const coarse = Math.min(v.t.max_lod, v.target + 2);
        const backdrop = coarse > v.target ? tiles(v, coarse, 2) : [];
        if (backdrop.length <= 40) wanted.push(...backdrop.filter((x) => !have(x)));
      }
    }
    const keys = new Set(wanted.map((x) => x.key));
    for (const [key, f] of inflight) {
      if (!keys.has(key)) {
        f.ctrl.abort();
        inflight.delete(key);
      }
    }
    // A tile in flight that will not cover what shows is grown once it
    // has arrived.
    queue = wanted.filter((x) => !inflight.has(x.key));
    for (const x of queue) {
      const e = cache.get(x.key);
      x.r = e ? union(e.r, x.need) : x.need;
      x.url = v.url(x.lod, x.i, x.j, x.r);
    }
    pump();
  }

  function pump() {
    clearTimeout(retryTimer);
    retryTimer = null;
    const now = performance.now();
    let wait = Infinity;
    for (let n = 0; n < queue.length && inflight.size < Math.floor(limit);) {
      const tile = queue[n];
      const at = retryAt.get(tile.key) || 0;
      if (at > now) {
        wait = Math.min(wait, at - now);
        n++;
        continue;
      }
      queue.splice(n, 1);
      fetchTile(tile);
    }
    if (wait < Infinity) retryTimer = setTimeout(pump, wait + 10);
  }

  async function fetchTile(tile) {
    const ctrl = new AbortController();
    inflight.set(tile.key, { ctrl, r: tile.r });
    try {
      const res = await fetch(tile.url, { signal: ctrl.signal });
      if (res.status === 503 || res.status === 429 || res.status === 409) {
        // Overloaded, or the texture still being precomputed: ask again
        // after Retry-After.
        const ra = Number(res.headers.get("Retry-After"));
        if (res.status !== 409) limit = Math.max(1, limit / 2);
        retryAt.set(tile.key, performance.now() + 1000 * (Number.isFinite(ra) && ra > 0 ? Math.min(ra, 30) : 1));
        const msg = await errorText(res);
        if (res.status === 409 && !/pending/.test(msg)) failed.set(tile.key, msg);
        return;
      }
      if (!res.ok) {
        const msg = await errorText(res);
        failed.set(tile.key, msg);
        if (!errorShown) say(`could not draw a tile: ${msg}`, true);
        errorShown = true;
        return;
      }
      const bmp = await createImageBitmap(await res.blob());
      if (ctrl.signal.aborted) {
        if (bmp.close) bmp.close();
        return;
      }
      retryAt.delete(tile.key);
      limit = Math.min(MAX_INFLIGHT, limit + 0.25);
      put(tile.key, bmp, tile.r);
      canvas.dataset.drawn = String(Number(canvas.dataset.drawn) + 1);
      requestDraw();
    } catch (e) {
      if (e.name === "AbortError" || ctrl.signal.aborted) return;
      // The connection failed: the server may be restarting.
      retryAt.set(tile.key, performance.now() + 2000);
      say(`could not load a tile: ${e.message}; retrying`, true);
    } finally {
      const f = inflight.get(tile.key);
      if (f && f.ctrl === ctrl) {
        inflight.delete(tile.key);
        if (!ctrl.signal.aborted) schedule();
      }
    }
  }

  // Redraws at once from the cache; asks for missing tiles now
  // (`immediate`) or within a few frames while the view keeps moving.
  function invalidate(immediate) {
    if (!state.selected || state.selected.status !== "ready" || !planar()) return;
    canvas.dataset.complete = "0";
    canvas.dataset.covered = "0";
    requestDraw();
    updateDownloads();
    if (immediate) schedule();
    else if (!fetchTimer) fetchTimer = setTimeout(schedule, 100);
  }

  function clear(text) {
    for (const [, f] of inflight) f.ctrl.abort();
    inflight.clear();
    queue = [];
    failed.clear();
    retryAt.clear();
    errorShown = false;
    const [W, H] = size();
    ctx.fillStyle = "#0d0e10";
    ctx.fillRect(0, 0, W, H);
    canvas.dataset.complete = "0";
    $("progress").firstChild.style.width = "0";
    hudText = text || "";
    $("hud").textContent = hudText;
    fieldUi.draw(null);
  }

  /// Sets scale (clamped) keeping the plane point under (mx, my) CSS
  /// pixels from the canvas centre in place.
  function zoomAt(scale, mx, my) {
    const before = [state.center[0] + mx / state.scale, state.center[1] + my / state.scale];
    state.scale = Math.max(minScale(), Math.min(MAX_SCALE, scale));
    state.center = [before[0] - mx / state.scale, before[1] - my / state.scale].map(clampCoord);
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
    state.center = [drag.c[0] - (e.clientX - drag.x) / state.scale, drag.c[1] - (e.clientY - drag.y) / state.scale].map(clampCoord);
    invalidate(false);
  });
  const endDrag = (e) => {
    if (drag) {
      // A click that did not move is a point for the field panel, at the
      // plane coordinates (finest voxels) under the pointer.
      const moved = Math.hypot(e.clientX - drag.x, e.clientY - drag.y);
      if (e.type === "pointerup" && moved < 4 && state.field.drawing) {
        const r = canvas.getBoundingClientRect();
        state.center = drag.c;
        fieldUi.click(
          state.center[0] + (e.clientX - r.left - r.width / 2) / state.scale,
          state.center[1] + (e.clientY - r.top - r.height / 2) / state.scale,
        );
      }
      invalidate(true);
    }
    drag = null;
  };
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const r = canvas.getBoundingClientRect();
    zoomAt(state.scale * Math.exp(-e.deltaY * 0.0015), e.clientX - r.left - r.width / 2, e.clientY - r.top - r.height / 2);
    invalidate(false);
  }, { passive: false });
  // The canvas follows its box (the controls wrap, the window resizes):
  // the first image and every later one fill it.
  new ResizeObserver(() => {
    size();
    if (planar()) invalidate(false);
  }).observe(canvas);

  return {
    invalidate, clear, draw, targetLod, view: currentView,
    pan(dx, dy) {
      state.center = [state.center[0] + dx / state.scale, state.center[1] + dy / state.scale].map(clampCoord);
      invalidate(false);
    },
    zoom(f) {
      zoomAt(state.scale * f, 0, 0);
      invalidate(false);
    },
    /// Sets any of { mode, axis, position, center, scale } and asks for
    /// that view at once.
    setView(o) {
      if (o.axis) {
        state.axis = o.axis;
        $("axis").value = o.axis;
      }
      if (o.center) state.center = o.center.map(clampCoord);
      if (o.position != null) setPosition(o.position);
      if (o.scale != null) state.scale = Math.max(minScale(), Math.min(MAX_SCALE, o.scale));
      if (o.mode && o.mode !== state.mode) setMode(o.mode);
      else if (state.mode === "solid") solid.invalidate();
      else if (state.mode === "mesh") meshView.bake();
      else invalidate(true);
    },
    stats: () => ({ cached: cache.size, inflight: inflight.size, queued: queue.length, failed: failed.size }),
  };
})();

// ---------------------------------------------------------------------
// 3D preview (WebGL2 ray casting through one brick)

/// A linked WebGL2 program; `attributes` get locations 0, 1, … in order.
function glProgram(gl, vs, fs, attributes) {
  const sh = (type, src) => {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  const prog = gl.createProgram();
  gl.attachShader(prog, sh(gl.VERTEX_SHADER, vs));
  gl.attachShader(prog, sh(gl.FRAGMENT_SHADER, fs));
  attributes.forEach((n, i) => gl.bindAttribLocation(prog, i, n));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  return prog;
}

const solid = (() => {
  const canvas = $("solid");
  let gl = null, prog = null, tex = null, loaded = null, shown = false, controller = null, uniforms = {};
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
    uniform float aspect, sphere, carve, texel;
    uniform vec3 cutNormal;
    float lum(vec3 q) { return dot(texture(volume, q).rgb, vec3(0.299, 0.587, 0.114)); }
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
      vec3 q = clamp(p * 0.5 + 0.5, 0.0, 1.0);
      vec3 rgb = texture(volume, q).rgb;
      // Relief: the luminance as a height of two voxels, its slope along
      // the surface tilting the normal, so that veins and pores catch the
      // light.
      vec3 g = vec3(lum(q + vec3(texel, 0, 0)) - lum(q - vec3(texel, 0, 0)),
                    lum(q + vec3(0, texel, 0)) - lum(q - vec3(0, texel, 0)),
                    lum(q + vec3(0, 0, texel)) - lum(q - vec3(0, 0, texel)));
      g -= normal * dot(g, normal);
      vec3 nb = normalize(normal - g);
      vec3 key = normalize(-dir + vec3(-0.35, -0.55, 0.0));
      float light = 0.32 + 0.78 * max(dot(nb, key), 0.0);
      float spec = pow(max(dot(nb, normalize(key - dir)), 0.0), 40.0) * 0.15;
      color = vec4(rgb * light + spec, 1.0);
    }`;

  function init() {
    if (gl) return true;
    gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true });
    if (!gl) return false;
    prog = glProgram(gl, VS, FS, []);
    gl.useProgram(prog);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
    const loc = gl.getAttribLocation(prog, "corner");
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
    for (const n of ["volume", "eye", "right", "up", "fwd", "aspect", "sphere", "carve", "cutNormal", "texel"]) {
      uniforms[n] = gl.getUniformLocation(prog, n);
    }
    tex = gl.createTexture();
    return true;
  }

  function render() {
    if (!gl || !shown) return;
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
    if (!webglReady(init, "the 3D preview")) return;
    const e = t.brick_size;
    const c = { x: 0, y: 0, z: 0 };
    const frame = { z: ["x", "y"], x: ["y", "z"], y: ["z", "x"] }[state.axis];
    c[frame[0]] = state.center[0];
    c[frame[1]] = state.center[1];
    c[state.axis] = state.position;
    let lod = state.blockLod ?? 0;
    const brick = (l) => ["x", "y", "z"].map((a) => Math.floor(c[a] / 2 ** l / e));
    const key = `${t.id}/${lod}/${brick(lod).join("_")}`;
    if (loaded === key) {
      render();
      return;
    }
    if (controller) controller.abort();
    const ctrl = new AbortController();
    controller = ctrl;
    const get = async (url) => {
      const res = await fetch(url, { signal: ctrl.signal });
      if (!res.ok) {
        const err = new Error(await errorText(res));
        err.status = res.status;
        throw err;
      }
      return new Uint8Array(await res.arrayBuffer());
    };
    // The same block at the coarsest level first (a few voxels, quick),
    // drawn until the chosen level arrives.
    let fine = null;
    const coarseLod = Math.min(t.max_lod, lod + 3, lod + Math.log2(e) - 1);
    if (coarseLod > lod) {
      const f = 2 ** (coarseLod - lod), n = e / f, o = brick(lod).map((x) => (x * e) / f);
      get(`${API}/${t.id}/region.raw?x=${o[0]}&y=${o[1]}&z=${o[2]}&w=${n}&h=${n}&d=${n}&lod=${coarseLod}`)
        .then((data) => {
          if (!fine && controller === ctrl) upload(data, n, coarseLod, `coarse preview at lod ${coarseLod} while lod ${lod} loads…`);
        })
        .catch(() => {});
    }
    // The chosen level, or the finest the server's work budget allows.
    for (;;) {
      const b = brick(lod);
      $("hud").textContent = `loading brick ${b.join(", ")} at lod ${lod} (${e}³ voxels)…`;
      try {
        fine = await get(`${API}/${t.id}/bricks/${lod}/${b.join("_")}.raw`);
        break;
      } catch (err) {
        if (err.name === "AbortError") return;
        if (err.status === 400 && /over_budget|too_large/.test(err.message) && lod < t.max_lod) {
          lod++;
          continue;
        }
        say(`could not load the brick: ${err.message}`, true);
        return;
      }
    }
    if (controller !== ctrl) return;
    upload(fine, e, lod, null);
    loaded = key;
    const b = brick(lod);
    $("hud").textContent = `brick ${b.join(", ")} · lod ${lod} · ${e}³ voxels · drag to orbit, wheel to zoom`;
    render();
  }

  function upload(data, n, lod, hud) {
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_3D, tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGB8, n, n, n, 0, gl.RGB, gl.UNSIGNED_BYTE, data);
    gl.useProgram(prog);
    gl.uniform1f(uniforms.texel, 1 / n);
    gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    for (const w of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) {
      gl.texParameteri(gl.TEXTURE_3D, w, gl.CLAMP_TO_EDGE);
    }
    canvas.dataset.lod = String(lod);
    shown = true;
    if (hud) {
      $("hud").textContent = hud;
      render();
    }
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
    shown = false;
    if (gl) {
      gl.clearColor(0.08, 0.085, 0.1, 1);
      gl.clear(gl.COLOR_BUFFER_BIT);
    }
  }

  return { invalidate, render, clear, orbit(dy, dp) { state.orbit.yaw += dy; state.orbit.pitch = Math.max(-89, Math.min(89, state.orbit.pitch + dp)); render(); } };
})();


// ---------------------------------------------------------------------
// Mesh view: a model baked through the bake route, lit so that the
// texture's relief shows, cut by a plane whose cap is the solid's own
// image on that plane (the cut route).

/// The model shipped with the repository (tests/fixtures/meshes/torus.obj,
/// CC0 1.0), written the way its generator torus.py writes it.
function torusObj() {
  const RINGS = 48, SIDES = 24, R = 1.0, r = 0.35, f = (x) => x.toFixed(6);
  const lines = ["# torus, 48 x 24 quads, generated by torus.py (CC0 1.0)"];
  for (let i = 0; i <= RINGS; i++) {
    const a = (2 * Math.PI * i) / RINGS;
    for (let j = 0; j <= SIDES; j++) {
      const b = (2 * Math.PI * j) / SIDES;
      const x = (R + r * Math.cos(b)) * Math.cos(a), y = (R + r * Math.cos(b)) * Math.sin(a), z = r * Math.sin(b);
      lines.push(`v ${f(x)} ${f(y)} ${f(z)}`);
    }
  }
  for (let i = 0; i <= RINGS; i++) for (let j = 0; j <= SIDES; j++) lines.push(`vt ${f(i / RINGS)} ${f(j / SIDES)}`);
  const W = SIDES + 1;
  for (let i = 0; i < RINGS; i++) {
    for (let j = 0; j < SIDES; j++) {
      const a = i * W + j + 1, b = (i + 1) * W + j + 1, c = (i + 1) * W + j + 2, d = i * W + j + 2;
      lines.push(`f ${a}/${a} ${b}/${b} ${c}/${c} ${d}/${d}`);
    }
  }
  return lines.join("\n") + "\n";
}

/// The parts of a glTF binary the mesh view draws: positions, normals,
/// texture coordinates or colours, indices and the base colour image.
function parseGlb(buf) {
  const dv = new DataView(buf);
  if (buf.byteLength < 28 || dv.getUint32(0, true) !== 0x46546c67) throw new Error("not a glTF binary");
  const jsonLen = dv.getUint32(12, true);
  const doc = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 20, jsonLen)));
  const binStart = 20 + jsonLen + 8;
  const bin = new Uint8Array(buf, binStart, dv.getUint32(20 + jsonLen, true));
  const view = (i) => {
    const v = doc.bufferViews[i];
    return bin.slice(v.byteOffset || 0, (v.byteOffset || 0) + v.byteLength);
  };
  const SIZE = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4 };
  const accessor = (i) => {
    const a = doc.accessors[i];
    const bytes = view(a.bufferView).slice(a.byteOffset || 0);
    const n = a.count * SIZE[a.type];
    if (a.componentType === 5126) return new Float32Array(bytes.buffer, 0, n);
    if (a.componentType === 5125) return new Uint32Array(bytes.buffer, 0, n);
    if (a.componentType === 5123) return Uint32Array.from(new Uint16Array(bytes.buffer, 0, n));
    throw new Error(`accessor component type ${a.componentType}`);
  };
  const prim = doc.meshes[0].primitives[0];
  const at = prim.attributes;
  const out = {
    positions: accessor(at.POSITION),
    normals: at.NORMAL != null ? accessor(at.NORMAL) : null,
    uvs: at.TEXCOORD_0 != null ? accessor(at.TEXCOORD_0) : null,
    colours: at.COLOR_0 != null ? accessor(at.COLOR_0) : null,
    indices: prim.indices != null ? accessor(prim.indices) : null,
    image: null,
  };
  const mat = doc.materials && doc.materials[prim.material || 0];
  const bct = mat && mat.pbrMetallicRoughness && mat.pbrMetallicRoughness.baseColorTexture;
  if (bct) {
    const img = doc.images[doc.textures[bct.index].source];
    out.image = new Blob([view(img.bufferView)], { type: img.mimeType });
  }
  return out;
}

// 4×4 matrices, column-major as WebGL reads them.
const mat4 = {
  mul(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
    return o;
  },
  perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
  },
  lookAt(eye, at, up) {
    const sub = (a, b) => a.map((x, i) => x - b[i]);
    const norm = (a) => { const l = Math.hypot(...a); return a.map((x) => x / l); };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
  },
};

const CAP_PART = 160; // side of the parts a cap is asked for in

const meshView = (() => {
  const canvas = $("mesh");
  let gl = null, prog = null, u = {};
  let model = null; // { vao, count, tex, lo, hi, longest, resolution, key }
  let cap = null; // { tex, key, url, w, h, pixels }
  let capWant = null, capCtrl = null, bakeCtrl = null;
  let source = { name: "torus.obj (shipped, CC0)", body: null, format: "obj" };
  const cam = { yaw: 35, pitch: 28, distance: 2.6 };
  canvas.dataset.drawn = "0";

  const VS = `#version 300 es
    in vec3 position;
    in vec3 normal;
    in vec2 uv;
    in vec3 colour;
    uniform mat4 viewProj;
    out vec3 vPos;
    out vec3 vNormal;
    out vec2 vUv;
    out vec3 vColour;
    void main() {
      vPos = position; vNormal = normal; vUv = uv; vColour = colour;
      gl_Position = viewProj * vec4(position, 1.0);
    }`;
  // Base colour from the baked texture (or the cap's cut image); a bump
  // from its luminance (surface gradient of the height, without tangents)
  // so that the grain and pores catch the light; a warm key light, a cool
  // fill, sky and ground ambient and a little gloss.
  const FS = `#version 300 es
    precision highp float;
    in vec3 vPos;
    in vec3 vNormal;
    in vec2 vUv;
    in vec3 vColour;
    uniform sampler2D base;
    uniform int useTexture;
    uniform vec4 clipPlane; // keeps dot(n, p) <= d
    uniform int clip;
    uniform vec3 eye;
    uniform float bump;
    uniform vec3 keyDir;
    out vec4 color;
    void main() {
      if (clip == 1 && dot(clipPlane.xyz, vPos) > clipPlane.w) discard;
      vec3 albedo = useTexture == 1 ? texture(base, vUv).rgb : vColour;
      vec3 n = normalize(vNormal);
      vec3 v = normalize(eye - vPos);
      if (dot(n, v) < 0.0) n = -n;
      float h = dot(albedo, vec3(0.299, 0.587, 0.114)) * bump;
      vec3 dpdx = dFdx(vPos), dpdy = dFdy(vPos);
      vec3 r1 = cross(dpdy, n), r2 = cross(n, dpdx);
      float det = dot(dpdx, r1);
      vec3 grad = sign(det) * (dFdx(h) * r1 + dFdy(h) * r2);
      n = normalize(abs(det) * n - grad);
      // The key light follows the camera (above and to its left), so that
      // whatever faces the viewer, caps included, is lit from one side.
      vec3 key = normalize(keyDir), fill = normalize(-keyDir + vec3(0.0, -0.3, 0.0));
      float sky = 0.5 + 0.5 * n.y;
      vec3 ambient = mix(vec3(0.10, 0.09, 0.08), vec3(0.22, 0.24, 0.28), sky);
      vec3 light = ambient + vec3(1.0, 0.93, 0.82) * max(dot(n, key), 0.0) * 0.9
                 + vec3(0.35, 0.42, 0.55) * max(dot(n, fill), 0.0) * 0.45;
      float spec = pow(max(dot(n, normalize(key + v)), 0.0), 40.0) * 0.18;
      vec3 rgb = albedo * light + spec;
      color = vec4(pow(rgb, vec3(1.0 / 1.1)), 1.0);
    }`;

  function init() {
    if (gl) return true;
    gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, stencil: true, antialias: true });
    if (!gl) return false;
    prog = glProgram(gl, VS, FS, ["position", "normal", "uv", "colour"]);
    for (const n of ["viewProj", "base", "useTexture", "clipPlane", "clip", "eye", "bump", "keyDir"]) u[n] = gl.getUniformLocation(prog, n);
    return true;
  }

  function buffer(loc, data, size) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
  }

  function texture(img) {
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, img);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    return t;
  }

  /// Bakes the model for the selected texture and shows it.
  async function bake() {
    const t = state.selected;
    if (!t || t.status !== "ready" || state.mode !== "mesh") return;
    if (!webglReady(init, "the mesh view")) return;
    const resolution = Number($("mesh-res").value);
    const body = source.body || torusObj();
    const key = `${t.id}|${source.name}|${resolution}`;
    if (model && model.key === key) {
      render();
      updateCap();
      return;
    }
    if (bakeCtrl) bakeCtrl.abort();
    const ctrl = new AbortController();
    bakeCtrl = ctrl;
    canvas.dataset.baked = "0";
    const t0 = performance.now();
    $("hud").textContent = `baking ${source.name} at resolution ${resolution}…`;
    let parts;
    try {
      const q = `resolution=${resolution}&filter=trilinear&format=${source.format}`;
      const res = await fetch(`${API}/${encodeURIComponent(t.id)}/bake?${q}`, {
        method: "POST", body, signal: ctrl.signal,
        headers: { "Content-Type": source.format === "obj" ? "text/plain" : "model/gltf-binary" },
      });
      if (!res.ok) throw new Error(await errorText(res));
      parts = parseGlb(await res.arrayBuffer());
      if (parts.image) parts.bitmap = await createImageBitmap(parts.image);
    } catch (e) {
      if (e.name !== "AbortError") {
        say(`could not bake ${source.name}: ${e.message}`, true);
        $("hud").textContent = "";
      }
      return;
    }
    if (bakeCtrl !== ctrl) return;
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    buffer(0, parts.positions, 3);
    if (parts.normals) buffer(1, parts.normals, 3);
    else gl.vertexAttrib3f(1, 0, 0, 1);
    if (parts.uvs) buffer(2, parts.uvs, 2);
    if (parts.colours) buffer(3, parts.colours.length === parts.positions.length ? parts.colours : rgbOf(parts.colours), 3);
    else gl.vertexAttrib3f(3, 0.7, 0.7, 0.7);
    const ib = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
    const indices = parts.indices || Uint32Array.from(parts.positions.filter((_, i) => i % 3 === 0).map((_, i) => i));
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    // The bake route's placement (unturned, from the origin): the bounding
    // box's longest side spans `resolution` voxels from its lowest corner.
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < parts.positions.length; i += 3) {
      for (let a = 0; a < 3; a++) {
        lo[a] = Math.min(lo[a], parts.positions[i + a]);
        hi[a] = Math.max(hi[a], parts.positions[i + a]);
      }
    }
    if (model) dispose(model);
    model = {
      vao, count: indices.length, tex: parts.bitmap ? texture(parts.bitmap) : null, lo, hi,
      longest: Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]), resolution, key,
      triangles: indices.length / 3, texels: parts.bitmap ? `${parts.bitmap.width}×${parts.bitmap.height}` : "vertex colours",
      seconds: (performance.now() - t0) / 1000,
    };
    if (parts.bitmap && parts.bitmap.close) parts.bitmap.close();
    canvas.dataset.baked = "1";
    canvas.dataset.triangles = String(model.triangles);
    render();
    updateCap();
  }

  function rgbOf(rgba) {
    const out = new Float32Array((rgba.length / 4) * 3);
    for (let i = 0, k = 0; i < rgba.length; i += 4) for (let c = 0; c < 3; c++) out[k++] = rgba[i + c];
    return out;
  }

  function dispose(m) {
    gl.deleteVertexArray(m.vao);
    if (m.tex) gl.deleteTexture(m.tex);
  }

  /// The cutting plane in the model's units: normal n (the oblique cut's),
  /// offset d through the box centre moved by the plane slider, and the
  /// cap: a square on the plane around the box, with the cut route's URL
  /// of the solid's image over it at about one pixel per voxel.
  function capPlane() {
    if (!model) return null;
    const { u: U, v: V, n } = cutBasis();
    const c0 = [0, 1, 2].map((a) => (model.lo[a] + model.hi[a]) / 2);
    const half = Math.hypot(...[0, 1, 2].map((a) => model.hi[a] - model.lo[a])) / 2;
    const d = n[0] * c0[0] + n[1] * c0[1] + n[2] * c0[2] + state.meshCut * half;
    const c = c0.map((x, a) => x + (d - (n[0] * c0[0] + n[1] * c0[1] + n[2] * c0[2])) * n[a]);
    const scale = model.resolution / model.longest; // voxels per model unit
    const N = Math.max(16, Math.min(1024, Math.ceil(2 * half * scale)));
    const step = (2 * half) / N; // model units per cap pixel
    // Voxel coordinates of a model point: (p − lo)·scale (the bake's
    // offset is 0); cap pixel (a, b) samples its centre.
    const vox = (p) => p.map((x, a) => (x - model.lo[a]) * scale);
    const corner = c.map((x, a) => x + (step / 2 - half) * (U[a] + V[a]));
    const f = (a) => a.map((x) => (Math.abs(x) < 5e-7 ? 0 : x).toFixed(6)).join(",");
    const o = vox(corner), du = U.map((x) => x * step * scale), dv = V.map((x) => x * step * scale);
    // The cut route's image of the square, from pixel (a, b), w × h.
    const part = (a, b, w, h) => `${API}/${encodeURIComponent(state.selected.id)}/cut.png?` +
      `origin=${f(o.map((x, k) => x + a * du[k] + b * dv[k]))}&u=${f(du)}&v=${f(dv)}&w=${w}&h=${h}&lod=0&filter=trilinear`;
    return { n, d, c, U, V, half, N, url: part(0, 0, N, N), part };
  }

  /// Asks for the cap's image when the plane moved (the latest plane wins).
  async function updateCap() {
    const p = capPlane();
    if (!p || (cap && cap.url === p.url) || capWant === p.url) return;
    capWant = p.url;
    if (capCtrl) capCtrl.abort();
    const ctrl = new AbortController();
    capCtrl = ctrl;
    canvas.dataset.capped = "0";
    try {
      // In parts of CAP_PART² pixels: the whole square at once can be over
      // the server's work budget for one request.
      const img = new OffscreenCanvas(p.N, p.N);
      const g = img.getContext("2d");
      const parts = [];
      for (let b = 0; b < p.N; b += CAP_PART) for (let a = 0; a < p.N; a += CAP_PART) parts.push([a, b]);
      const next = async () => {
        for (let x; (x = parts.shift());) {
          const [a, b] = x;
          const res = await fetch(p.part(a, b, Math.min(CAP_PART, p.N - a), Math.min(CAP_PART, p.N - b)), { signal: ctrl.signal });
          if (!res.ok) throw new Error(await errorText(res));
          const bmp = await createImageBitmap(await res.blob());
          g.drawImage(bmp, a, b);
          if (bmp.close) bmp.close();
        }
      };
      await Promise.all([next(), next(), next()]);
      if (capCtrl !== ctrl) return;
      if (cap && cap.tex) gl.deleteTexture(cap.tex);
      cap = { tex: texture(img), url: p.url, img };
      canvas.dataset.capped = "1";
      canvas.dataset.cap = p.url;
      render();
    } catch (e) {
      if (e.name !== "AbortError") say(`could not load the cap: ${e.message}`, true);
    } finally {
      if (capWant === p.url) capWant = null;
    }
  }

  let capQuad = null;
  function drawCap(p) {
    if (!capQuad) {
      capQuad = { vao: gl.createVertexArray(), pos: gl.createBuffer() };
      gl.bindVertexArray(capQuad.vao);
      gl.bindBuffer(gl.ARRAY_BUFFER, capQuad.pos);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      const uv = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, uv);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([0, 0, 1, 0, 1, 1, 0, 0, 1, 1, 0, 1]), gl.STATIC_DRAW);
      gl.enableVertexAttribArray(2);
      gl.vertexAttribPointer(2, 2, gl.FLOAT, false, 0, 0);
      gl.bindVertexArray(null);
    }
    const at = (s, t) => p.c.map((x, a) => x + p.half * (s * p.U[a] + t * p.V[a]));
    const q = [at(-1, -1), at(1, -1), at(1, 1), at(-1, -1), at(1, 1), at(-1, 1)].flat();
    gl.bindVertexArray(capQuad.vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, capQuad.pos);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(q), gl.DYNAMIC_DRAW);
    gl.vertexAttrib3f(1, ...p.n); // the cap faces the removed side
    gl.drawArrays(gl.TRIANGLES, 0, 6);
    gl.bindVertexArray(null);
  }

  function render() {
    if (!gl || !model || state.mode !== "mesh") return;
    const [w, h] = fitCanvas(canvas);
    gl.viewport(0, 0, w, h);
    gl.clearColor(0.075, 0.08, 0.095, 1);
    gl.clearStencil(0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT | gl.STENCIL_BUFFER_BIT);
    const centre = [0, 1, 2].map((a) => (model.lo[a] + model.hi[a]) / 2);
    const size = model.longest;
    const cy = Math.cos((cam.yaw * Math.PI) / 180), sy = Math.sin((cam.yaw * Math.PI) / 180);
    const cp = Math.cos((cam.pitch * Math.PI) / 180), sp = Math.sin((cam.pitch * Math.PI) / 180);
    const dist = cam.distance * size;
    const eye = [centre[0] + dist * cp * sy, centre[1] + dist * sp, centre[2] + dist * cp * cy];
    const viewProj = mat4.mul(mat4.perspective(0.6, w / h, size * 0.05, size * 20), mat4.lookAt(eye, centre, [0, 1, 0]));
    gl.useProgram(prog);
    gl.uniformMatrix4fv(u.viewProj, false, viewProj);
    gl.uniform3fv(u.eye, eye);
    // Towards the camera, turned 35° to its left and 25° up.
    const ky = ((cam.yaw - 35) * Math.PI) / 180, kp = (Math.max(-60, Math.min(80, cam.pitch + 25)) * Math.PI) / 180;
    gl.uniform3f(u.keyDir, Math.cos(kp) * Math.sin(ky), Math.sin(kp), Math.cos(kp) * Math.cos(ky));
    gl.uniform1i(u.base, 0);
    gl.activeTexture(gl.TEXTURE0);
    const p = capPlane();
    const cutting = state.meshCut < 0.999;
    gl.uniform4f(u.clipPlane, p.n[0], p.n[1], p.n[2], p.d);
    gl.uniform1i(u.clip, cutting ? 1 : 0);
    // Relief of a few voxels, in model units.
    gl.uniform1f(u.bump, (3 * model.longest) / model.resolution);
    gl.enable(gl.DEPTH_TEST);
    gl.disable(gl.CULL_FACE);
    gl.disable(gl.STENCIL_TEST);
    gl.uniform1i(u.useTexture, model.tex ? 1 : 0);
    if (model.tex) gl.bindTexture(gl.TEXTURE_2D, model.tex);
    gl.bindVertexArray(model.vao);
    gl.drawElements(gl.TRIANGLES, model.count, gl.UNSIGNED_INT, 0);
    if (cutting && cap) {
      // Where the plane lies inside the solid, the kept surfaces behind it
      // are crossed an odd number of times: the stencil's parity marks
      // the cap.
      gl.enable(gl.STENCIL_TEST);
      gl.stencilFunc(gl.ALWAYS, 0, 0xff);
      gl.stencilOp(gl.KEEP, gl.KEEP, gl.INVERT);
      gl.colorMask(false, false, false, false);
      gl.depthMask(false);
      gl.disable(gl.DEPTH_TEST);
      gl.drawElements(gl.TRIANGLES, model.count, gl.UNSIGNED_INT, 0);
      gl.colorMask(true, true, true, true);
      gl.depthMask(true);
      gl.enable(gl.DEPTH_TEST);
      gl.stencilFunc(gl.NOTEQUAL, 0, 0xff);
      gl.stencilOp(gl.KEEP, gl.KEEP, gl.KEEP);
      gl.uniform1i(u.clip, 0);
      gl.uniform1i(u.useTexture, 1);
      gl.bindTexture(gl.TEXTURE_2D, cap.tex);
      drawCap(p);
      gl.disable(gl.STENCIL_TEST);
    }
    gl.bindVertexArray(null);
    canvas.dataset.drawn = String(Number(canvas.dataset.drawn) + 1);
    $("hud").textContent = `${source.name} · ${model.triangles} triangles · resolution ${model.resolution} · texture ${model.texels}` +
      ` · baked in ${model.seconds.toFixed(1)} s\ndrag to orbit, shift-drag or the plane slider to move the cut, wheel to zoom`;
  }

  // Orbit with the mouse; with Shift held a drag moves the plane along its
  // normal.
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    canvas.focus();
    drag = { x: e.clientX, y: e.clientY, yaw: cam.yaw, pitch: cam.pitch, cut: state.meshCut, shift: e.shiftKey };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    if (drag.shift) {
      const r = canvas.getBoundingClientRect();
      setCut(drag.cut - ((e.clientY - drag.y) / r.height) * 2, false);
      return;
    }
    cam.yaw = drag.yaw - (e.clientX - drag.x) * 0.4;
    cam.pitch = Math.max(-89, Math.min(89, drag.pitch + (e.clientY - drag.y) * 0.4));
    render();
  });
  const end = () => {
    if (drag && drag.shift) updateCap();
    drag = null;
  };
  canvas.addEventListener("pointerup", end);
  canvas.addEventListener("pointercancel", end);
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    cam.distance = Math.max(0.8, Math.min(8, cam.distance * Math.exp(e.deltaY * 0.001)));
    render();
  }, { passive: false });
  new ResizeObserver(() => render()).observe(canvas);

  /// Moves the plane: -1 … 1 across the model, 1 leaves it whole.
  function setCut(x, settled) {
    state.meshCut = Math.max(-1, Math.min(1, x));
    $("mesh-cut").value = String(Math.round(state.meshCut * 100));
    $("mesh-cut-out").textContent = state.meshCut.toFixed(2);
    render();
    if (settled !== false) updateCap();
    else scheduleCap();
  }
  let capTimer = null;
  function scheduleCap() {
    clearTimeout(capTimer);
    capTimer = setTimeout(updateCap, 120);
  }

  /// A mesh file the user chose or dropped: OBJ or glTF binary.
  async function load(file) {
    const buf = await file.arrayBuffer();
    const head = new Uint8Array(buf, 0, Math.min(4, buf.byteLength));
    const glb = head.length === 4 && String.fromCharCode(...head) === "glTF";
    source = { name: file.name, body: buf, format: glb ? "glb" : "obj" };
    model = null;
    cap = null;
    bake();
  }
  $("mesh-file").addEventListener("change", () => {
    const f = $("mesh-file").files[0];
    if (f) load(f);
  });
  $("mesh-torus").addEventListener("click", () => {
    source = { name: "torus.obj (shipped, CC0)", body: null, format: "obj" };
    bake();
  });
  canvas.addEventListener("dragover", (e) => e.preventDefault());
  canvas.addEventListener("drop", (e) => {
    e.preventDefault();
    e.stopPropagation();
    const f = e.dataTransfer && e.dataTransfer.files[0];
    if (f) load(f);
  });

  return {
    bake, render, setCut, torusObj, capPlane,
    /// The cap's pixels as shown (RGBA), for checking against the cut route.
    capPixels() {
      if (!cap) return null;
      const c = cap.img;
      return { url: cap.url, w: c.width, h: c.height, data: Array.from(c.getContext("2d").getImageData(0, 0, c.width, c.height).data) };
    },
    model: () => model && { lo: model.lo, hi: model.hi, longest: model.longest, resolution: model.resolution, triangles: model.triangles },
    orbit(dy, dp) { cam.yaw += dy; cam.pitch = Math.max(-89, Math.min(89, cam.pitch + dp)); render(); },
  };
})();

// ---------------------------------------------------------------------
// Controls

function setMode(mode) {
  state.mode = mode;
  for (const b of document.querySelectorAll("nav .tab")) b.classList.toggle("active", b.dataset.mode === mode);
  for (const l of document.querySelectorAll(".controls [data-for]")) {
    l.hidden = !l.dataset.for.split(" ").includes(mode);
  }
  $("plane").hidden = !planar();
  $("overlay").hidden = mode !== "slice";
  $("solid").hidden = mode !== "solid";
  $("mesh").hidden = mode !== "mesh";
  $("progress").hidden = mode === "solid" || mode === "mesh";
  if (mode === "solid") solid.invalidate();
  else if (mode === "mesh") meshView.bake();
  else plane.invalidate(true);
  updateDownloads();
}

function bindRange(id, apply, fmt) {
  const input = $(id), out = $(`${id}-out`);
  const update = (settled) => {
    apply(Number(input.value));
    if (out) out.textContent = fmt ? fmt(Number(input.value)) : input.value;
    if (state.mode === "solid") {
      if (id === "position") solid.invalidate();
      else solid.render();
      updateDownloads();
    } else if (state.mode === "mesh") {
      meshView.setCut(state.meshCut, settled);
    } else {
      plane.invalidate(settled);
    }
  };
  input.addEventListener("input", () => update(false));
  input.addEventListener("change", () => update(true));
}

/// Moves the slice (or the cut's offset) to `p`, any integer in the
/// coordinate range; the slider spans ±512 around where it was typed.
function setPosition(p) {
  p = clampCoord(Math.trunc(p));
  state.position = p;
  const at = $("at"), slider = $("position");
  if (document.activeElement !== at || Number(at.value) !== p) at.value = String(p);
  if (p < Number(slider.min) || p > Number(slider.max)) {
    const lo = Math.max(COORD_MIN, Math.min(COORD_MAX - 1024, p - 512));
    slider.min = String(lo);
    slider.max = String(lo + 1024);
  }
  slider.value = String(p);
}

function movePosition(p, settled) {
  setPosition(p);
  if (state.mode === "solid") {
    solid.invalidate();
    updateDownloads();
  } else {
    plane.invalidate(settled);
  }
}

function setupControls() {
  $("inset").addEventListener("click", () => $("inset").classList.toggle("big"));
  for (const b of document.querySelectorAll("nav .tab")) b.addEventListener("click", () => setMode(b.dataset.mode));
  $("axis").addEventListener("change", () => {
    state.axis = $("axis").value;
    plane.invalidate(true);
  });
  const slider = $("position");
  slider.addEventListener("input", () => movePosition(Number(slider.value), false));
  slider.addEventListener("change", () => movePosition(Number(slider.value), true));
  const at = $("at");
  at.addEventListener("change", () => {
    const p = Number(at.value.trim());
    if (at.value.trim() === "" || !Number.isFinite(p)) {
      at.value = String(state.position);
      say(`a position is an integer within ${COORD_MIN} … ${COORD_MAX}`, true);
      return;
    }
    if (p < COORD_MIN || p > COORD_MAX) say(`position clamped to the coordinate range ${COORD_MIN} … ${COORD_MAX}`, true);
    at.value = String(clampCoord(Math.trunc(p)));
    movePosition(p, true);
  });
  at.addEventListener("keydown", (e) => {
    if (e.key === "Enter") at.dispatchEvent(new Event("change"));
  });
  bindRange("yaw", (v) => { state.yaw = v; });
  bindRange("pitch", (v) => { state.pitch = v; });
  bindRange("carve", (v) => { state.carve = v / 100; }, (v) => (v / 100).toFixed(2));
  bindRange("mesh-cut", (v) => { state.meshCut = v / 100; }, (v) => (v / 100).toFixed(2));
  $("mesh-res").addEventListener("change", () => meshView.bake());
  $("shape").addEventListener("change", () => {
    state.shape = $("shape").value;
    solid.render();
  });
  $("block-lod").addEventListener("change", () => {
    state.blockLod = Number($("block-lod").value);
    solid.invalidate();
    updateDownloads();
  });
  window.addEventListener("keydown", (e) => {
    const tag = e.target.tagName;
    if (tag === "INPUT" || tag === "SELECT" || tag === "TEXTAREA" || e.ctrlKey || e.metaKey || e.altKey) return;
    const k = e.key.toLowerCase();
    const step = e.shiftKey ? 16 : 1;
    if (k === "s") setMode("slice");
    else if (k === "c") setMode("cut");
    else if (k === "v") setMode("solid");
    else if (k === "m") setMode("mesh");
    else if ("xyz".includes(k) && k.length === 1) {
      state.axis = k;
      $("axis").value = k;
      plane.invalidate(true);
    } else if (k === "[" || k === "pagedown") {
      movePosition(state.position - step, false);
    } else if (k === "]" || k === "pageup") {
      movePosition(state.position + step, false);
    } else if (k.startsWith("arrow")) {
      e.preventDefault();
      const d = { arrowleft: [-1, 0], arrowright: [1, 0], arrowup: [0, -1], arrowdown: [0, 1] }[k];
      if (state.mode === "solid") solid.orbit(d[0] * 5, d[1] * 5);
      else if (state.mode === "mesh") meshView.orbit(d[0] * 5, d[1] * 5);
      else plane.pan(d[0] * 40, d[1] * 40);
    } else if (k === "+" || k === "=") {
      plane.zoom(1.25);
    } else if (k === "-") {
      plane.zoom(0.8);
    }
  });
}

// ---------------------------------------------------------------------
// Field panel: a field of local frames for the selected texture (a preset
// or curves clicked on the slice), applied as a variant of it; arrows of
// the field's local x axis and the curves drawn over the slice.

const fieldUi = (() => {
  const overlay = $("overlay");
  const ctx = overlay.getContext("2d");
  // World axes (indices) of a slice's u and v and of its normal, as
  // slices are laid out.
  const PLANE = { z: [0, 1, 2], x: [1, 2, 0], y: [2, 0, 1] };
  const MAX_SAMPLES = 4096; // the frames route's limit
  const MAX_SIDE = 4096;
  const SPACING = 56; // CSS pixels between arrows
  let frames = null; // the last frames answer, with the texture's id
  let framesUrl = null; // the frames asked for last
  let ctrl = null;
  let timer = null;
  overlay.dataset.arrows = "0";
  overlay.dataset.points = "0";

  const kind = () => $("f-kind").value;

  const describe = describeField;

  function setDrawing(on) {
    state.field.drawing = on;
    $("f-draw").setAttribute("aria-pressed", String(on));
    if (on) say("click on the slice to add points to the curve (drag to pan); Apply when done");
  }

  function showKind() {
    const k = kind();
    for (const el of $("field-panel").querySelectorAll("[data-kinds]")) {
      el.hidden = !el.dataset.kinds.split(" ").includes(k);
    }
    if (k !== "sketch" && state.field.drawing) setDrawing(false);
    renderCurves();
  }

  function number(id, what) {
    const text = $(id).value.trim();
    const v = Number(text);
    if (text === "" || !Number.isFinite(v)) throw new Error(`${what} must be a number`);
    return v;
  }

  /// Three numbers from "x,y,z".
  function vec3(id, what) {
    const v = $(id).value.split(",").map((x) => Number(x.trim()));
    if (v.length !== 3 || !v.every(Number.isFinite)) throw new Error(`${what} must be three numbers x,y,z`);
    return v;
  }

  /// The field the panel describes, as the API takes it (null for none).
  function field() {
    const k = kind();
    if (k === "slant") return { kind: k, angle: number("f-angle", "the angle") };
    if (k === "zigzag") return { kind: k, angle: number("f-angle", "the angle"), period: number("f-period", "the period") };
    if (k === "circular" || k === "emissive") {
      const axis = [0, 0, 0];
      axis["xyz".indexOf($("f-axis").value)] = 1;
      return { kind: k, centre: vec3("f-centre", "the centre"), axis };
    }
    if (k === "slant3d") return { kind: k, direction: vec3("f-direction", "the direction") };
    if (k === "sketch") {
      const along = $("f-along").value;
      const curves = state.field.curves
        .filter((c) => c.points.length >= 2)
        .map((c) => ({ points: c.points, normal: c.normal, along }));
      if (!curves.length) throw new Error("draw a curve of two points or more on the slice first (Draw, then click)");
      return { kind: k, curves };
    }
    return null;
  }

  function renderCurves() {
    const cs = state.field.curves;
    const points = cs.reduce((n, c) => n + c.points.length, 0);
    $("f-curves").textContent = cs.length
      ? `${cs.length} curve${cs.length > 1 ? "s" : ""}, ${points} points; normal to the slice they were drawn on`
      : "no curves yet: press Draw and click on the slice";
  }

  /// A click on the slice at plane coordinates (u, v), finest voxels:
  /// the next point of the curve being drawn.
  function click(u, v) {
    if (!state.field.drawing || state.mode !== "slice") return;
    const [iu, iv, n] = PLANE[state.axis];
    const p = [0, 0, 0];
    p[iu] = Math.round(u * 100) / 100;
    p[iv] = Math.round(v * 100) / 100;
    p[n] = state.position;
    const f = state.field;
    let c = f.curves[f.current];
    // A curve lies on one slice: a point on another starts a new curve.
    if (!c || c.axis !== state.axis || c.at !== state.position) {
      if (f.curves.length >= 32) {
        say("a field takes at most 32 curves", true);
        return;
      }
      const normal = [0, 0, 0];
      normal[n] = 1;
      c = { points: [], normal, axis: state.axis, at: state.position };
      f.curves.push(c);
      f.current = f.curves.length - 1;
    }
    if (c.points.length >= 256) {
      say("a curve takes at most 256 points: start a new curve", true);
      return;
    }
    const last = c.points[c.points.length - 1];
    if (last && last.every((x, i) => x === p[i])) return;
    c.points.push(p);
    renderCurves();
  }

  /// Asks for the frames that the view `v` shows, unless asked already.
  function want(v) {
    const lod = v.target, k = 2 ** lod;
    let step = Math.max(1, Math.round((SPACING * dpr()) / (k * v.ps)));
    const x0 = (v.cx - v.W / 2 / v.ps) / k, x1 = (v.cx + v.W / 2 / v.ps) / k;
    const y0 = (v.cy - v.H / 2 / v.ps) / k, y1 = (v.cy + v.H / 2 / v.ps) / k;
    // On the step's grid, so that panning keeps the arrows in place.
    const grid = () => {
      const u0 = Math.floor(x0 / step) * step, v0 = Math.floor(y0 / step) * step;
      const w = Math.min(MAX_SIDE, Math.ceil((x1 - u0) / step + 1) * step);
      const h = Math.min(MAX_SIDE, Math.ceil((y1 - v0) / step + 1) * step);
      return { u0, v0, w, h };
    };
    let g = grid();
    while (Math.ceil(g.w / step) * Math.ceil(g.h / step) > MAX_SAMPLES) {
      step *= 2;
      g = grid();
    }
    // Within the coordinate range: the last sample at most 2^31.
    const fit = (o, n) => Math.max(COORD_MIN, Math.min(COORD_MAX + 2 - n, o));
    const at = Math.floor(state.position / k);
    const url = `${API}/${encodeURIComponent(v.t.id)}/frames/${state.axis}/${at}.json?u0=${fit(g.u0, g.w)}` +
      `&v0=${fit(g.v0, g.h)}&w=${g.w}&h=${g.h}&step=${step}&lod=${lod}`;
    if (url === framesUrl) return;
    framesUrl = url;
    clearTimeout(timer);
    timer = setTimeout(() => load(url, v.t.id), 120);
  }

  async function load(url, id) {
    if (ctrl) ctrl.abort();
    const mine = (ctrl = new AbortController());
    try {
      const res = await fetch(url, { signal: mine.signal });
      if (!res.ok) {
        // Busy or not ready yet: asked again at the next draw.
        if (res.status === 409 || res.status === 503) framesUrl = null;
        else say(`could not read the field: ${await errorText(res)}`, true);
        return;
      }
      frames = { ...(await res.json()), id };
      draw(plane.view());
    } catch (e) {
      if (e.name !== "AbortError") {
        framesUrl = null;
        say(`could not read the field: ${e.message}`, true);
      }
    }
  }

  /// Local x arrows, each as long as the axis's part in the slice; a ring
  /// where it leaves the slice. Returns how many were drawn.
  function arrows(v, f) {
    const k = 2 ** f.lod;
    const L = Math.min(0.8 * f.step * k * v.ps, 48 * dpr());
    const path = new Path2D();
    let n = 0;
    for (const s of f.samples) {
      const x = ((s.u + 0.5) * k - v.cx) * v.ps + v.W / 2;
      const y = ((s.v + 0.5) * k - v.cy) * v.ps + v.H / 2;
      if (x < -L || y < -L || x > v.W + L || y > v.H + L) continue;
      const [du, dv] = s.x;
      if (Math.hypot(du, dv) < 0.2) {
        path.moveTo(x + L * 0.12, y);
        path.arc(x, y, L * 0.12, 0, 2 * Math.PI);
      } else {
        const hx = (du * L) / 2, hy = (dv * L) / 2;
        const tx = x + hx, ty = y + hy;
        const m = Math.hypot(hx, hy), ux = hx / m, uy = hy / m, head = Math.min(m, L * 0.22);
        path.moveTo(x - hx, y - hy);
        path.lineTo(tx, ty);
        path.moveTo(tx - head * (ux - uy * 0.6), ty - head * (uy + ux * 0.6));
        path.lineTo(tx, ty);
        path.lineTo(tx - head * (ux + uy * 0.6), ty - head * (uy - ux * 0.6));
      }
      n++;
    }
    ctx.lineCap = "round";
    ctx.lineJoin = "round";
    ctx.strokeStyle = "rgba(12, 13, 15, .8)";
    ctx.lineWidth = 4 * dpr();
    ctx.stroke(path);
    ctx.strokeStyle = "#d9a441";
    ctx.lineWidth = 1.6 * dpr();
    ctx.stroke(path);
    return n;
  }

  /// The curves drawn on slices of the current axis (dashed when on
  /// another slice than this one). Returns how many points were drawn.
  function curves(v) {
    const [iu, iv] = PLANE[state.axis];
    let n = 0;
    state.field.curves.forEach((c, i) => {
      if (c.axis !== state.axis || !c.points.length) return;
      const pts = c.points.map((p) => [(p[iu] - v.cx) * v.ps + v.W / 2, (p[iv] - v.cy) * v.ps + v.H / 2]);
      ctx.setLineDash(c.at === state.position ? [] : [6 * dpr(), 5 * dpr()]);
      ctx.strokeStyle = i === state.field.current ? "#ffd27a" : "#f2f2f2";
      ctx.lineWidth = 2 * dpr();
      ctx.beginPath();
      pts.forEach(([x, y], j) => (j ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
      ctx.stroke();
      ctx.setLineDash([]);
      ctx.fillStyle = ctx.strokeStyle;
      for (const [x, y] of pts) {
        ctx.beginPath();
        ctx.arc(x, y, 3 * dpr(), 0, 2 * Math.PI);
        ctx.fill();
      }
      n += pts.length;
    });
    return n;
  }

  /// Redraws the overlay over the view `v` (none: cleared).
  function draw(v) {
    const plane = $("plane");
    if (overlay.width !== plane.width || overlay.height !== plane.height) {
      overlay.width = plane.width;
      overlay.height = plane.height;
    }
    ctx.clearRect(0, 0, overlay.width, overlay.height);
    let drawn = 0, points = 0;
    if (v && v.mode === "slice") {
      if (state.field.arrows) {
        want(v);
        if (frames && frames.id === v.t.id && frames.axis === state.axis) drawn = arrows(v, frames);
      }
      points = curves(v);
    }
    overlay.dataset.arrows = String(drawn);
    overlay.dataset.points = String(points);
  }

  /// Makes the selected texture follow the panel's field: asks for the
  /// variant and shows it once ready.
  async function apply() {
    const t = state.selected;
    if (!t || t.status !== "ready") {
      say("select a ready texture first", true);
      return;
    }
    let f;
    try {
      f = field();
    } catch (e) {
      say(e.message, true);
      return;
    }
    const button = $("f-apply");
    button.setAttribute("aria-disabled", "true");
    let res;
    try {
      res = await fetch(`${API}/${encodeURIComponent(t.id)}/variants`, {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ field: f }),
      });
    } catch (e) {
      say(`could not apply the field: ${e.message}`, true);
      return;
    } finally {
      button.removeAttribute("aria-disabled");
    }
    if (!res.ok) {
      say(`field refused: ${await errorText(res)}`, true);
      return;
    }
    const made = await res.json();
    setDrawing(false);
    if (made.id === t.id) {
      say(`${label(t)} has ${describe(f)} already`);
      return;
    }
    // The view stays where it is: only the texture changes.
    await refreshList();
    const now = state.textures.find((x) => x.id === made.id);
    if (made.status === "ready" && now) {
      say(`${label(now)} with ${describe(f)}`);
      select(now);
    } else {
      state.uploading = made.id;
      say(`making ${label(made)} with ${describe(f)}…`);
    }
  }

  /// Shows the selected texture's field.
  function selected() {
    const t = state.selected;
    $("f-current").textContent = t ? `this texture: ${describe(t.params && t.params.field)}` : "";
  }

  $("f-kind").addEventListener("change", () => {
    const k = kind();
    if (k === "circular" || k === "emissive") {
      // About the view's centre, around the slice's axis: rings in view.
      const c = centreVoxel();
      $("f-centre").value = [c.x, c.y, c.z].join(",");
      $("f-axis").value = state.axis;
    }
    showKind();
    if (k === "sketch" && state.mode === "slice") setDrawing(true);
  });
  $("f-draw").addEventListener("click", () => setDrawing(!state.field.drawing));
  $("f-new").addEventListener("click", () => {
    state.field.current = -1;
    renderCurves();
    draw(plane.view());
  });
  $("f-clear").addEventListener("click", () => {
    state.field.curves = [];
    state.field.current = -1;
    renderCurves();
    draw(plane.view());
  });
  $("f-apply").addEventListener("click", apply);
  $("f-arrows").addEventListener("change", () => {
    state.field.arrows = $("f-arrows").checked;
    draw(plane.view());
  });
  showKind();

  return { draw, click, selected, field, apply };
})();

// Exposed for tests and for poking at from the console.
window.solidtex = { state, select, setMode, upload, setView: plane.setView, stats: plane.stats, field: fieldUi, mesh: meshView };

window.addEventListener("hashchange", followAddress);
window.addEventListener("popstate", followAddress);
setupUpload();
setupDownloads();
setupControls();
setMode("slice");
refreshList();
setInterval(refreshList, 1000);
