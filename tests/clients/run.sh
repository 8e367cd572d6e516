#!/usr/bin/env bash
# Reads a live `solidtex serve` with the real clients:
#  - test_formats.py: zarr-python, tensorstore (zarr3 and
#    neuroglancer_precomputed drivers) and cloud-volume, byte for byte
#    against region.raw;
#  - viewer.test.mjs: the browser viewer in headless Chromium;
#  - viewer_zoom.test.mjs: how soon the viewer shows a cold view sharp;
#  - viewer_mesh.test.mjs: the viewer baking the shipped torus and cutting it;
#  - neuroglancer.test.mjs: Neuroglancer itself rendering the texture;
#  - test_exports.py: pynrrd and numpy reading the NRRD and raw exports,
#    ome-zarr-models validating the OME-Zarr view;
#  - exports.test.mjs: ktx-parse and three.js (KTX2Loader in Chromium)
#    reading the KTX2 exports, and the shader example's seams;
#  - meshes.test.mjs: Khronos' glTF validator on baked meshes;
#  - three_bake.test.mjs: three.js's GLTFLoader drawing baked meshes.
#
#   tests/clients/run.sh [path/to/solidtex]
#   tests/clients/run.sh --install     # only install the clients
#
# Installs what it needs into target/clients/ (ignored): a Python virtual
# environment, playwright-core, and Debian's chromium when it is missing.
# Screenshots are left in target/clients/artefacts/.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
C=$ROOT/target/clients
mkdir -p "$C"

# Python clients, pinned.
if [ ! -x "$C/venv/bin/python" ]; then
    python3 -m venv "$C/venv"
fi
if ! cmp -s tests/clients/requirements.txt "$C/venv/requirements.txt"; then
    PIP_CACHE_DIR=$C/pip-cache "$C/venv/bin/pip" install --quiet --disable-pip-version-check \
        -r tests/clients/requirements.txt
    cp tests/clients/requirements.txt "$C/venv/requirements.txt"
fi

# playwright-core drives the system's Chromium (it downloads no browser);
# three.js and ktx-parse read the KTX2 exports; gltf-validator checks
# baked meshes.
NODE_PACKAGES="playwright-core@1.65.1 three@0.187.0 ktx-parse@2.0.0 gltf-validator@2.0.0-dev.3.10"
if [ "$(cat "$C/node/packages.txt" 2>/dev/null)" != "$NODE_PACKAGES" ]; then
    mkdir -p "$C/node"
    # shellcheck disable=SC2086
    (cd "$C/node" && echo '{"private": true}' >package.json &&
        npm_config_cache=$C/npm-cache npm install --no-audit --no-fund --silent $NODE_PACKAGES)
    echo "$NODE_PACKAGES" >"$C/node/packages.txt"
fi
if [ ! -x /usr/bin/chromium ]; then
    SUDO=
    [ "$(id -u)" -eq 0 ] || SUDO=sudo
    $SUDO apt-get update -q >/dev/null
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q chromium >/dev/null
fi

[ "${1:-}" = --install ] && exit 0

export SOLIDTEX_BIN=${1:-${SOLIDTEX_BIN:-${CARGO_TARGET_DIR:-target}/release/solidtex}}
[ -x "$SOLIDTEX_BIN" ] || cargo build --release --bin solidtex
SOLIDTEX_BIN=$(realpath "$SOLIDTEX_BIN")
export CLIENTS_NODE_DIR=$C/node CLIENTS_ARTEFACTS=$C/artefacts
(cd tests/clients && "$C/venv/bin/python" -m pytest -q -p no:cacheprovider test_formats.py test_exports.py)
node tests/clients/viewer.test.mjs
node tests/clients/viewer_zoom.test.mjs
node tests/clients/viewer_mesh.test.mjs
PYTHON=$C/venv/bin/python node tests/clients/neuroglancer.test.mjs
node tests/clients/exports.test.mjs
node tests/clients/meshes.test.mjs
node tests/clients/three_bake.test.mjs
