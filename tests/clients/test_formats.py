"""The precomputed and Zarr views read by the real clients (zarr-python,
tensorstore's zarr3 and neuroglancer_precomputed drivers, cloud-volume)
must give, byte for byte, what `region.raw` gives for the same box, with
the chunks compressed (the server's default: zstd for Zarr, gzip for
precomputed to clients that accept it) and raw.

Boxes are drawn at random (fixed seed) so that they straddle chunk
boundaries on every axis; some lie far from the origin, at the window's
edges. Reads are small and mostly at coarse levels of detail, because
every chunk a client touches is synthesized on demand.
"""

import random
import time

import numpy as np
import pytest

from serve import Server

CHUNK = 16


@pytest.fixture(scope="module", params=["compressed", "raw"])
def server(request):
    s = Server(chunk_size=CHUNK, compression=request.param == "compressed")
    yield s
    s.stop()


def boxes(max_lod):
    """(x, y, z, w, h, d, lod) in texture coordinates of level `lod`."""
    rng = random.Random(6)
    out = []
    for lod in (max_lod, max_lod, max_lod - 1, 0):
        half = 1 << (19 - lod)
        # Near the origin, then far from it (inside the window, both signs).
        for centre in (0, rng.choice((-1, 1)) * rng.randrange(half // 2, half - 64)):
            size = [rng.randrange(3, 10) for _ in range(3)]
            # Start a few voxels before a chunk boundary: every axis straddles.
            start = [
                (centre // CHUNK + rng.randrange(-2, 2)) * CHUNK - rng.randrange(1, s)
                for s in size
            ]
            out.append((*start, *size, lod))
    # The first voxels of the window at the coarsest level.
    first = -(1 << (19 - max_lod))
    out.append((first, first, first, 5, 4, 3, max_lod))
    return out


def reference(server, box):
    x, y, z, w, h, d, lod = box
    raw = server.region(x, y, z, w, h, d, lod)
    return np.frombuffer(raw, np.uint8).reshape(d, h, w, 3)


def czyx(box, lod_origin):
    """Zarr slices (c, z, y, x) of a box: indices are shifted by the window."""
    x, y, z, w, h, d, _ = box
    o = -lod_origin
    return (slice(None), slice(z + o, z + o + d), slice(y + o, y + o + h), slice(x + o, x + o + w))


def channel_last(a):
    """(c, z, y, x) -> (z, y, x, c), the layout of `region.raw`."""
    return np.moveaxis(np.asarray(a), 0, -1)


def origin(lod):
    return -(1 << (19 - lod))


def check(name, box, got, want):
    assert got.shape == want.shape, f"{name} {box}: shape {got.shape} != {want.shape}"
    assert got.dtype == np.uint8, f"{name} {box}: dtype {got.dtype}"
    if not np.array_equal(got, want):
        bad = np.argwhere(got != want)
        raise AssertionError(f"{name} {box}: {len(bad)} bytes differ, first at {bad[0]}")
    assert want.std() > 0, f"{box}: reference is flat"


def test_zarr_python(server):
    import zarr

    group = zarr.open_group(f"{server.url}/zarr", mode="r", zarr_format=3)
    levels = group.attrs["solidtex"]["levels"]
    assert [lv["path"] for lv in levels] == [str(k) for k in range(server.max_lod + 1)]
    for box in boxes(server.max_lod):
        lod = box[-1]
        arr = group[str(lod)]
        assert arr.shape == (3,) + (1 << (20 - lod),) * 3
        assert arr.chunks == (3, CHUNK, CHUNK, CHUNK)
        t0 = time.time()
        got = channel_last(arr[czyx(box, origin(lod))])
        print(f"zarr-python {box}: {time.time() - t0:.2f} s")
        check("zarr-python", box, got, reference(server, box))


def test_tensorstore_zarr3(server):
    import tensorstore as ts

    for box in boxes(server.max_lod):
        lod = box[-1]
        arr = ts.open({"driver": "zarr3", "kvstore": f"{server.url}/zarr/{lod}/"}).result()
        assert arr.domain.shape == (3,) + (1 << (20 - lod),) * 3
        assert arr.dtype == ts.uint8
        got = arr[czyx(box, origin(lod))].read().result()
        check("tensorstore zarr3", box, channel_last(got), reference(server, box))


def test_tensorstore_precomputed(server):
    import tensorstore as ts

    for box in boxes(server.max_lod):
        x, y, z, w, h, d, lod = box
        arr = ts.open({
            "driver": "neuroglancer_precomputed",
            "kvstore": f"{server.url}/precomputed/",
            "scale_index": lod,
        }).result()
        # The voxel offset makes the domain the texture's own coordinates.
        assert list(arr.domain.inclusive_min) == [origin(lod)] * 3 + [0]
        got = arr[x:x + w, y:y + h, z:z + d, :].read().result()
        # (x, y, z, c) -> (z, y, x, c)
        got = np.transpose(np.asarray(got), (2, 1, 0, 3))
        check("tensorstore precomputed", box, got, reference(server, box))


def test_cloud_volume(server):
    from cloudvolume import CloudVolume

    for box in boxes(server.max_lod):
        x, y, z, w, h, d, lod = box
        vol = CloudVolume(
            f"precomputed://{server.url}/precomputed",
            mip=lod,
            progress=False,
            cache=False,
            fill_missing=False,
        )
        assert vol.num_channels == 3
        assert list(vol.voxel_offset) == [origin(lod)] * 3
        got = np.asarray(vol[x:x + w, y:y + h, z:z + d])
        got = np.transpose(got, (2, 1, 0, 3))
        check("cloud-volume", box, got, reference(server, box))
