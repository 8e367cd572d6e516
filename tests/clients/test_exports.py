"""Exports and the OME-Zarr view, read by tools that are not ours:

- pynrrd reads the NRRD export: its voxels are `region.raw`'s, its
  spacing and origin place them in finest voxels;
- numpy reads the raw export as its sidecar JSON says, and Pillow the
  slice atlas, each tile a z slice where the sidecar places it;
- ome-zarr-models validates the Zarr hierarchy as an OME-Zarr 0.5 image:
  one dataset per level of detail, axes c, z, y, x, scales 2^lod.

(ome-zarr's own reader is not run: it builds a dask array over the whole
2^20-voxel window and exhausts memory before reading a chunk.)
"""

import json
import os
import tempfile

import numpy as np
import pytest

from serve import Server, get

PERIOD = 32


@pytest.fixture(scope="module")
def server():
    s = Server(chunk_size=16, params=f"&period={PERIOD}")
    yield s
    s.stop()


def region(server, x, y, z, w, h, d, lod):
    raw = server.region(x, y, z, w, h, d, lod)
    return np.frombuffer(raw, np.uint8).reshape(d, h, w, 3)


def test_pynrrd_reads_the_nrrd_export(server):
    import nrrd

    box = dict(x=-3, y=5, z=2, w=11, h=7, d=5, lod=1)
    query = "&".join(f"{k}={v}" for k, v in box.items())
    body = get(f"{server.url}/export?format=nrrd&{query}")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "box.nrrd")
        with open(path, "wb") as f:
            f.write(body)
        data, header = nrrd.read(path)
    # pynrrd's default index order is NRRD's own: (channel, x, y, z).
    assert data.shape == (3, 11, 7, 5)
    assert data.dtype == np.uint8
    want = region(server, **box)
    assert np.array_equal(np.transpose(data, (3, 2, 1, 0)), want)
    assert list(header["kinds"]) == ["RGB-color", "domain", "domain", "domain"]
    directions = np.asarray(header["space directions"], dtype=float)
    assert np.allclose(directions[1:], 2 * np.eye(3)), directions
    # Voxel (x, y, z) of lod 1 has its centre at 2·(x, y, z) + 0.5 finest.
    assert np.allclose(header["space origin"], [-5.5, 10.5, 4.5]), header["space origin"]


def test_numpy_reads_the_raw_export_by_its_sidecar(server):
    side = json.loads(get(f"{server.url}/export.json?format=raw&box=period"))
    assert side["tiles"] is True
    assert side["size"] == [PERIOD] * 3
    raw = get(f"{server.url}/export?format=raw&box=period")
    assert len(raw) == side["bytes"]
    data = np.frombuffer(raw, np.dtype(side["dtype"])).reshape(side["shape_zyxc"])
    assert np.array_equal(data, region(server, 0, 0, 0, PERIOD, PERIOD, PERIOD, 0))
    # One period tiles: the block one period along is the same.
    assert np.array_equal(data, region(server, PERIOD, -PERIOD, 3 * PERIOD, PERIOD, PERIOD, PERIOD, 0))


def test_ome_zarr_models_validates_the_hierarchy(server):
    import zarr
    from ome_zarr_models.v05.image import Image

    group = zarr.open_group(f"{server.url}/zarr", mode="r", zarr_format=3)
    image = Image.from_zarr(group)
    ms = image.ome_attributes.multiscales[0]
    assert [a.name for a in ms.axes] == ["c", "z", "y", "x"]
    assert [a.type for a in ms.axes] == ["channel", "space", "space", "space"]
    assert [d.path for d in ms.datasets] == [str(k) for k in range(server.max_lod + 1)]
    for k, dataset in enumerate(ms.datasets):
        scale = dataset.coordinateTransformations[0].scale
        assert list(scale) == [1.0] + [float(1 << k)] * 3


def test_pillow_reads_the_slice_atlas_by_its_sidecar(server):
    from PIL import Image

    box = dict(x=7, y=-4, z=3, w=12, h=9, d=5, lod=0)
    query = "&".join(f"{k}={v}" for k, v in box.items())
    side = json.loads(get(f"{server.url}/export.json?format=atlas&{query}"))
    layout = side["layout"]
    png = get(f"{server.url}/export?format=atlas&{query}")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "atlas.png")
        with open(path, "wb") as f:
            f.write(png)
        image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape == (layout["height"], layout["width"], 3)
    want = region(server, **box)
    w, h, columns = layout["tile_width"], layout["tile_height"], layout["columns"]
    for z in range(layout["slices"]):
        col, row = z % columns, z // columns
        tile = image[row * h:(row + 1) * h, col * w:(col + 1) * w]
        assert np.array_equal(tile, want[z]), f"slice {z}"
