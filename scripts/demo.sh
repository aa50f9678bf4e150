#!/usr/bin/env bash
# The main job on the built-in default: the solid sphere at level 9, corner balance, 2 ranks.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
bash scripts/setup.sh
mkdir -p target/demo
mpirun -np 2 target/release/octmesh mesh sphere --level 9 --balance corner --keep inside \
    --out target/demo/sphere.pvtu --stats target/demo/stats.json
echo "mesh written to target/demo/sphere.pvtu, statistics to target/demo/stats.json"
