#!/usr/bin/env bash
# The whole test suite: style, lints, unit tests, MPI tests on 1-4 ranks, p4est equality.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
bash scripts/setup.sh
cargo fmt --check
cargo clippy --release --all-targets --quiet -- -D warnings
cargo test --release 2>&1 | tee target/test.log
# One closing line for the whole run (cargo's last line is the doc-test summary).
awk '/test result:/ { for (i = 1; i <= NF; i++) { if ($i ~ /^passed/) p += $(i-1); if ($i ~ /^failed/) f += $(i-1) } }
     /^mpi_balance: / { p += $2; f += $4 }
     END { printf "tests: %d passed, %d failed\n", p, f }' target/test.log
