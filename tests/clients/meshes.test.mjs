// Baked meshes read by Khronos' glTF validator (npm `gltf-validator`):
// every bake the server answers (the mesh's own UVs, a generated atlas,
// vertex colours, trilinear reads, a cut and a fracture into pieces, a
// PLY, a GLB sent back in, a bake run as a background job) and one
// `solidtex bake` writes report no errors; the command line's file is the
// server's byte for byte. The files are left in ARTEFACTS.
//
//   node meshes.test.mjs

import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { createRequire } from "node:module";
import { join } from "node:path";
import { ARTEFACTS, ROOT, binary, startServer } from "./browser.mjs";

const NODE = process.env.CLIENTS_NODE_DIR || join(ROOT, "target", "clients", "node");
const require = createRequire(join(NODE, "package.json"));
const validator = require("gltf-validator");

const TORUS = join(ROOT, "tests", "fixtures", "meshes", "torus.obj");
mkdirSync(ARTEFACTS, { recursive: true });

async function validate(name, bytes) {
  writeFileSync(join(ARTEFACTS, `${name}.glb`), bytes);
  const report = await validator.validateBytes(bytes);
  const { numErrors, numWarnings } = report.issues;
  const errors = report.issues.messages.filter((m) => m.severity === 0);
  assert.equal(numErrors, 0, `${name}: ${JSON.stringify(errors.slice(0, 5), null, 1)}`);
  console.log(`${name}: valid glTF (${numWarnings} warnings)`);
}

const server = await startServer([], { defaultTexture: true });
try {
  const bake = async (query, body) => {
    const res = await fetch(`${server.base}/v1/textures/default/bake?${query}`, { method: "POST", body });
    assert.equal(res.status, 200, `${query}: ${await res.clone().text()}`);
    assert.equal(res.headers.get("content-type"), "model/gltf-binary");
    return new Uint8Array(await res.arrayBuffer());
  };
  const torus = readFileSync(TORUS);
  const own = await bake("resolution=64&uvs=mesh", torus);
  await validate("torus-mesh-uvs", own);
  await validate("torus-atlas", await bake("resolution=64&uvs=atlas", torus));
  await validate("torus-vertex-colours", await bake("resolution=64&colours=vertex", torus));
  await validate("torus-trilinear", await bake("resolution=48&uvs=atlas&filter=trilinear&rotation=30,0,45", torus));
  // Cut across the hole and through the ring: pieces as nodes, capped.
  await validate("torus-cut", await bake("resolution=48&cut=0,0,1,0", torus));
  await validate("torus-fracture", await bake("resolution=48&cut=0,0,1,0.05;1,0.3,0,-0.1&spread=0.1", torus));
  // The torus as an ASCII PLY, cut.
  const lines = torus.toString("utf8").split("\n");
  const vs = lines.filter((l) => l.startsWith("v ")).map((l) => l.slice(2));
  const fs = lines.filter((l) => l.startsWith("f ")).map((l) => l.slice(2).trim().split(/\s+/).map((t) => parseInt(t, 10) - 1));
  const ply = [
    "ply", "format ascii 1.0", `element vertex ${vs.length}`, "property float x", "property float y", "property float z",
    `element face ${fs.length}`, "property list uchar int vertex_indices", "end_header",
    ...vs, ...fs.map((f) => `${f.length} ${f.join(" ")}`), "",
  ].join("\n");
  await validate("torus-ply-cut", await bake("resolution=48&cut=1,0,0,0.1", ply));
  // The same bake as a background job: 202 with its status and Location,
  // progress that never goes back, then the very same file.
  const started = await fetch(`${server.base}/v1/textures/default/bake?resolution=64&uvs=mesh`, {
    method: "POST",
    body: torus,
    headers: { Prefer: "respond-async" },
  });
  assert.equal(started.status, 202, await started.clone().text());
  const job = started.headers.get("location");
  assert.match(job, /^\/v1\/bakes\/[0-9a-f]+$/);
  let status = await started.json();
  let progress = 0;
  for (let tries = 0; status.state !== "done"; tries++) {
    assert.ok(["queued", "running"].includes(status.state), JSON.stringify(status));
    assert.ok(status.progress >= progress, `progress went back: ${JSON.stringify(status)}`);
    progress = status.progress;
    assert.ok(tries < 600, "the bake job did not finish in a minute");
    await new Promise((r) => setTimeout(r, 100));
    status = await (await fetch(`${server.base}${job}`)).json();
  }
  assert.equal(status.progress, 1);
  const file = await fetch(`${server.base}${job}/file`);
  assert.equal(file.status, 200);
  assert.equal(file.headers.get("content-type"), "model/gltf-binary");
  const background = new Uint8Array(await file.arrayBuffer());
  assert.ok(Buffer.from(background).equals(Buffer.from(own)), "the background bake differs from the direct one");
  await validate("torus-background", background);
  // Deleting it frees the file.
  assert.equal((await fetch(`${server.base}${job}`, { method: "DELETE" })).status, 200);
  const gone = (await fetch(`${server.base}${job}/file`)).status;
  assert.ok(gone === 404 || gone === 410, `the deleted bake's file answered ${gone}`);
  // A baked GLB sent back in, on its own UVs.
  await validate("torus-rebaked", await bake("resolution=64&uvs=mesh&format=glb", own));
  const out = join(ARTEFACTS, "torus-cli.glb");
  execFileSync(binary(), ["bake", TORUS, "--resolution", "64", "--uvs", "mesh", "-o", out], {
    stdio: ["ignore", "inherit", "inherit"],
  });
  const cli = new Uint8Array(readFileSync(out));
  await validate("torus-cli", cli);
  assert.ok(Buffer.from(cli).equals(Buffer.from(own)), "the command line's bake differs from the server's");
} finally {
  await server.stop();
}
