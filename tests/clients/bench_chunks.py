"""Bytes and time per chunk, raw vs compressed: Zarr (zstd) and
precomputed (gzip), on the bundled texture, chunk size 32, lod 0 and 2.
Each chunk is fetched twice; the second (tiles cached) isolates encoding.
The precomputed chunks hold the voxels of the Zarr chunks fetched just
before, so even their first fetch finds the tiles cached.

    target/clients/venv/bin/python tests/clients/bench_chunks.py target/release/solidtex
"""
import subprocess, sys, tempfile, time, urllib.request, os, statistics
BIN = sys.argv[1]
def serve(compression):
    d = tempfile.mkdtemp()
    p = subprocess.Popen([BIN, "serve", "--addr", "127.0.0.1:0", "--data-dir", d + "/data",
                          "--chunk-compression", compression, "--log", "warn"], stdout=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    base = line.split("listening on ")[1].strip()
    for _ in range(600):
        try:
            urllib.request.urlopen(base + "/readyz"); break
        except Exception: time.sleep(0.2)
    return p, base
def fetch(url, gzip):
    req = urllib.request.Request(url, headers={"Accept-Encoding": "gzip"} if gzip else {})
    t = time.perf_counter(); body = urllib.request.urlopen(req).read(); return len(body), time.perf_counter() - t
rows = []
for compression in ["false", "true"]:
    p, base = serve(compression)
    t = base + "/v1/textures/default"
    for lod in (0, 2):
        o = (1 << (19 - lod)) // 32
        zs, zc, zw, ps, pc, pw = [], [], [], [], [], []
        for i in range(6):
            z = f"{t}/zarr/{lod}/c/0/{o}/{o}/{o + i}"
            n, cold = fetch(z, False); _, warm = fetch(z, False)
            zs.append(n); zc.append(cold); zw.append(warm)
            x0 = i * 32
            pre = f"{t}/precomputed/{lod}/{x0}-{x0 + 32}_0-32_0-32"
            n, cold = fetch(pre, True); _, warm = fetch(pre, True)
            ps.append(n); pc.append(cold); pw.append(warm)
        m = statistics.median
        rows.append((compression, lod, "zarr", m(zs), m(zc) * 1e3, m(zw) * 1e3))
        rows.append((compression, lod, "precomputed", m(ps), m(pc) * 1e3, m(pw) * 1e3))
    p.terminate(); p.wait()
print("| compression | lod | view | bytes per chunk | cold ms | warm ms |")
print("| --- | --- | --- | --- | --- | --- |")
for r in rows:
    print(f"| {'on' if r[0]=='true' else 'off'} | {r[1]} | {r[2]} | {r[3]:.0f} | {r[4]:.1f} | {r[5]:.1f} |")
