#!/usr/bin/env bash
# The main job on the built-in default: the sphere at level 9, corner balance, 2 ranks.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
bash scripts/setup.sh
mpirun -np 2 target/release/octmesh octree sphere --level 9 --balance corner --stats target/demo_stats.json
echo "statistics written to target/demo_stats.json"
