// Shared pieces of the browser tests: a real `solidtex serve`, Debian's
// Chromium driven by playwright-core, a static file server, and pixel
// statistics of screenshots (decoded by the browser itself, so the tests
// need no image library).

import { spawn } from "node:child_process";
import { mkdtempSync, readFileSync, rmSync, existsSync, statSync } from "node:fs";
import { createServer, request as httpRequest } from "node:http";
import { tmpdir } from "node:os";
import { join, dirname, extname, resolve, sep } from "node:path";
import { fileURLToPath } from "node:url";
import { createRequire } from "node:module";

export const HERE = dirname(fileURLToPath(import.meta.url));
export const ROOT = resolve(HERE, "..", "..");
const require = createRequire(join(process.env.CLIENTS_NODE_DIR || join(ROOT, "target", "clients", "node"), "package.json"));
const { chromium } = require("playwright-core");

/// Where screenshots go (kept as CI artefacts).
export const ARTEFACTS = process.env.CLIENTS_ARTEFACTS || join(ROOT, "target", "clients", "artefacts");

export function binary() {
  if (process.env.SOLIDTEX_BIN) return process.env.SOLIDTEX_BIN;
  return join(process.env.CARGO_TARGET_DIR || join(ROOT, "target"), "release", "solidtex");
}

/// Starts `solidtex serve` on a free loopback port with a fresh data
/// directory; resolves to { base, stop }. The bundled `default` texture is
/// off unless `options.defaultTexture`. With SOLIDTEX_VIEWER_DIR set, `base`
/// is a proxy that serves `/` and `/viewer.js` from that directory (the
/// viewer's sources, without rebuilding the binary) and forwards the rest.
export function startServer(extraArgs = [], options = {}) {
  const dir = mkdtempSync(join(tmpdir(), "solidtex-browser-"));
  const proc = spawn(binary(), [
    "serve", "--addr", "127.0.0.1:0", "--data-dir", join(dir, "data"),
    "--default-texture", options.defaultTexture ? "true" : "false", "--log", "warn", ...extraArgs,
  ], { stdio: ["ignore", "pipe", "inherit"] });
  return new Promise((ok, fail) => {
    let out = "", listening = false;
    proc.stdout.on("data", async (d) => {
      out += d;
      const m = out.match(/solidtex listening on (http:\/\/\S+)/);
      if (m && !listening) {
        listening = true;
        const proxy = process.env.SOLIDTEX_VIEWER_DIR ? await viewerProxy(m[1], process.env.SOLIDTEX_VIEWER_DIR) : null;
        ok({
          base: proxy ? proxy.base : m[1],
          server: m[1],
          async stop() {
            if (proxy) await proxy.stop();
            proc.kill("SIGTERM");
            await new Promise((r) => proc.once("exit", r));
            rmSync(dir, { recursive: true, force: true });
          },
        });
      }
    });
    proc.once("exit", (code) => fail(new Error(`server exited (${code}) before listening: ${out}`)));
  });
}

/// Serves the viewer's `index.html` and `viewer.js` from `dir` and forwards
/// every other request to `upstream`; resolves to { base, stop }.
function viewerProxy(upstream, dir) {
  const up = new URL(upstream);
  const server = createServer((req, res) => {
    const path = new URL(req.url, "http://x").pathname;
    if (req.method === "GET" && (path === "/" || path === "/viewer.js")) {
      res.writeHead(200, { "Content-Type": path === "/" ? "text/html" : "text/javascript" });
      res.end(readFileSync(join(dir, path === "/" ? "index.html" : "viewer.js")));
      return;
    }
    const fwd = httpRequest({ host: up.hostname, port: up.port, path: req.url, method: req.method, headers: req.headers }, (r) => {
      res.writeHead(r.statusCode, r.headers);
      r.pipe(res);
    });
    fwd.on("error", () => res.destroy());
    // A cancelled request is cancelled upstream too.
    res.on("close", () => { if (!res.writableFinished) fwd.destroy(); });
    req.pipe(fwd);
  });
  return new Promise((ok) => {
    server.listen(0, "127.0.0.1", () => {
      ok({
        base: `http://127.0.0.1:${server.address().port}`,
        stop: () => new Promise((r) => { server.closeAllConnections(); server.close(r); }),
      });
    });
  });
}

/// Waits until the bundled `default` texture (precomputed at start) is ready.
export async function defaultReady(base) {
  const deadline = Date.now() + 180_000;
  for (;;) {
    const t = await (await fetch(`${base}/v1/textures/default`)).json();
    if (t.status === "ready") return t;
    if (t.status !== "pending" || Date.now() > deadline) throw new Error(`the bundled texture: ${JSON.stringify(t)}`);
    await new Promise((r) => setTimeout(r, 250));
  }
}

/// Uploads an exemplar with query parameters and waits until it is ready.
export async function readyTexture(base, pngPath, query) {
  const res = await fetch(`${base}/v1/textures?${query}`, {
    method: "POST",
    headers: { "Content-Type": "image/png" },
    body: readFileSync(pngPath),
  });
  if (!res.ok) throw new Error(`upload: ${res.status} ${await res.text()}`);
  const { id } = await res.json();
  const deadline = Date.now() + 120_000;
  for (;;) {
    const t = await (await fetch(`${base}/v1/textures/${id}`)).json();
    if (t.status === "ready") return t;
    if (t.status !== "pending" || Date.now() > deadline) throw new Error(`texture ${id}: ${JSON.stringify(t)}`);
    await new Promise((r) => setTimeout(r, 100));
  }
}

const TYPES = {
  ".html": "text/html", ".js": "text/javascript", ".css": "text/css",
  ".wasm": "application/wasm", ".map": "application/json", ".json": "application/json",
};

/// Serves the files under `root` on a free loopback port; resolves to
/// { base, stop }.
export function serveStatic(root) {
  const server = createServer((req, res) => {
    const path = decodeURIComponent(new URL(req.url, "http://x").pathname);
    const file = resolve(root, "." + (path.endsWith("/") ? path + "index.html" : path));
    if (!file.startsWith(resolve(root) + sep) || !existsSync(file) || !statSync(file).isFile()) {
      res.writeHead(404).end();
      return;
    }
    res.writeHead(200, { "Content-Type": TYPES[extname(file)] || "application/octet-stream" });
    res.end(readFileSync(file));
  });
  return new Promise((ok) => {
    server.listen(0, "127.0.0.1", () => {
      ok({
        base: `http://127.0.0.1:${server.address().port}`,
        stop: () => new Promise((r) => server.close(r)),
      });
    });
  });
}

/// Headless Chromium with the flags this machine needs (no network beyond
/// loopback, no GPU: WebGL runs on SwiftShader) and a fresh profile.
/// Resolves to { context, close }.
export async function launch(viewport = { width: 1000, height: 640 }) {
  const profile = mkdtempSync(join(tmpdir(), "solidtex-chromium-"));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    viewport,
    args: [
      "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync",
      "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
    ],
  });
  return {
    context,
    async close() {
      await context.close();
      rmSync(profile, { recursive: true, force: true });
    },
  };
}

/// The three.js release the pages import from the CDN (their import maps
/// name it), served instead from node_modules: the pages run offline.
export const THREE_VERSION = "0.187.0";

/// Answers `context`'s requests for three.js on the CDN from node_modules.
export async function routeThree(context) {
  const dir = join(process.env.CLIENTS_NODE_DIR || join(ROOT, "target", "clients", "node"), "node_modules", "three");
  await context.route(`https://unpkg.com/three@${THREE_VERSION}/**`, (route) => {
    const path = new URL(route.request().url()).pathname.replace(`/three@${THREE_VERSION}/`, "");
    route.fulfill({ body: readFileSync(join(dir, path)), contentType: "text/javascript" });
  });
}

/// Mean and standard deviation of the pixels of a PNG (all channels), and
/// the fraction of grey pixels (r = g = b within 2), over the part inside
/// `box` {x, y, w, h} when given.
export async function pngStats(context, png, box) {
  const page = await context.newPage();
  try {
    return await page.evaluate(async ({ b64, box }) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement("canvas");
      c.width = img.width;
      c.height = img.height;
      const ctx = c.getContext("2d");
      ctx.drawImage(img, 0, 0);
      const r = box || { x: 0, y: 0, w: img.width, h: img.height };
      const d = ctx.getImageData(r.x, r.y, r.w, r.h).data;
      let sum = 0, sq = 0, n = 0, grey = 0;
      for (let i = 0; i < d.length; i += 4) {
        if (Math.abs(d[i] - d[i + 1]) <= 2 && Math.abs(d[i + 1] - d[i + 2]) <= 2) grey++;
        for (let k = 0; k < 3; k++) {
          sum += d[i + k];
          sq += d[i + k] * d[i + k];
          n++;
        }
      }
      const mean = sum / n;
      return { mean, std: Math.sqrt(Math.max(0, sq / n - mean * mean)), grey: grey / (n / 3) };
    }, { b64: png.toString("base64"), box });
  } finally {
    await page.close();
  }
}
