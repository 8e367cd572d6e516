#!/usr/bin/env bash
# The cluster test (tests/cluster/cluster.py): three replicas on one
# S3-compatible store behind HAProxy, on loopback.
#
#   bash tests/cluster/run.sh --install   # haproxy (Debian), s3s-fs (crates.io)
#   bash tests/cluster/run.sh             # needs target/release/solidtex
#   bash tests/cluster/run.sh --bench     # hit ratios and the balancer's cost
#
# The store is s3s-fs, pinned: a real S3 server (SigV4, path-style
# requests, If-None-Match and If-Match on PUT) that keeps each object as a
# file written to a temporary name and renamed, so objects survive a
# restart of the store; docs/cluster.md says why it was chosen.
set -euo pipefail
cd "$(dirname "$0")/../.."
S3S_VERSION=0.14.1
TOOLS="${SOLIDTEX_CLUSTER_TOOLS:-$HOME/.cache/solidtex-cluster}"

if [[ "${1:-}" == "--install" ]]; then
    if ! command -v haproxy >/dev/null; then
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends haproxy
    fi
    # Built apart from the workspace (its own target directory), once per
    # machine: cargo install does nothing when this version is there.
    cargo install s3s-fs --version "$S3S_VERSION" --features binary --locked \
        --root "$TOOLS" --target-dir "$TOOLS/target"
    rm -rf "$TOOLS/target"
    exit 0
fi

S3S_FS="$TOOLS/bin/s3s-fs"
[[ -x "$S3S_FS" ]] || { echo "no $S3S_FS: run $0 --install first" >&2; exit 1; }
command -v haproxy >/dev/null || { echo "no haproxy: run $0 --install first" >&2; exit 1; }
[[ -x target/release/solidtex ]] || cargo build --release --bin solidtex
# The whole test stops itself well inside CI's budget.
PYTHONDONTWRITEBYTECODE=1 S3S_FS="$S3S_FS" timeout --kill-after=10 600 python3 tests/cluster/cluster.py "$@"
