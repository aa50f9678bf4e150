#!/usr/bin/env bash
# Weak scaling on 1, 2, 4, 8 and 16 ranks at a fixed number of leaves per rank
# (sphere and dragon): per phase, the largest peak memory of a rank, the bytes
# one rank sends and receives and the collective operations, as Markdown tables
# (target/bench/weak_scaling.md) and PNG plots (docs/weak_scaling_*.png).
# Extra arguments go to tools/bench/weak_scaling.py (--np, --cases, --limit, ...).
# Exits non-zero when a phase grows past the limits against P = 2.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
cargo build --release --quiet
mkdir -p target/bench
exec /usr/bin/python3 tools/bench/weak_scaling.py --no-build \
  --json target/bench/weak_scaling.json --markdown target/bench/weak_scaling.md \
  --png docs/weak_scaling "$@"
