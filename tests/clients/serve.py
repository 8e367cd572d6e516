"""Starts a real `solidtex serve` for the client tests and uploads a small
exemplar, so that every test reads the same ready texture.

The server listens on a free loopback port with a fresh data directory and
no bundled texture; the exemplar is a 32x32 crop of the bundled one with
three pyramid levels, which precomputes in about a second.
"""

import json
import os
import pathlib
import subprocess
import tempfile
import time
import urllib.request

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
EXEMPLAR = HERE / "exemplar32.png"


def binary():
    """The solidtex binary: $SOLIDTEX_BIN, else the debug build."""
    if os.environ.get("SOLIDTEX_BIN"):
        return os.environ["SOLIDTEX_BIN"]
    target = os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target"))
    return str(pathlib.Path(target) / "debug" / "solidtex")


def get(url, timeout=300):
    with urllib.request.urlopen(url, timeout=timeout) as r:
        return r.read()


class Server:
    """A running server with one ready texture (`self.id`)."""

    def __init__(self, chunk_size=16, levels=3, compression=True, params=""):
        self.dir = tempfile.TemporaryDirectory(prefix="solidtex-clients-")
        self.log = open(os.path.join(self.dir.name, "server.log"), "w")
        self.proc = subprocess.Popen(
            [
                binary(), "serve",
                "--addr", "127.0.0.1:0",
                "--data-dir", os.path.join(self.dir.name, "data"),
                "--default-texture", "false",
                "--chunk-size", str(chunk_size),
                "--chunk-compression", "true" if compression else "false",
                "--log", "warn",
            ],
            stdout=subprocess.PIPE,
            stderr=self.log,
            text=True,
        )
        line = self.proc.stdout.readline()
        prefix = "solidtex listening on "
        if not line.startswith(prefix):
            self.stop()
            raise RuntimeError(f"server did not start: {line!r}")
        self.base = line[len(prefix):].strip()
        req = urllib.request.Request(
            f"{self.base}/v1/textures?levels={levels}{params}",
            data=EXEMPLAR.read_bytes(),
            headers={"Content-Type": "image/png"},
            method="POST",
        )
        with urllib.request.urlopen(req) as r:
            self.id = json.load(r)["id"]
        deadline = time.time() + 120
        while True:
            meta = json.loads(get(f"{self.base}/v1/textures/{self.id}"))
            if meta["status"] == "ready":
                break
            assert meta["status"] == "pending", meta
            assert time.time() < deadline, "precompute took too long"
            time.sleep(0.1)
        self.max_lod = meta["max_lod"]
        self.url = f"{self.base}/v1/textures/{self.id}"

    def region(self, x, y, z, w, h, d, lod):
        """`region.raw` as bytes, x fastest, then y, then z, RGB."""
        return get(f"{self.url}/region.raw?x={x}&y={y}&z={z}&w={w}&h={h}&d={d}&lod={lod}")

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.log.close()
        self.dir.cleanup()
