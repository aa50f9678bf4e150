#!/usr/bin/env bash
# The whole test suite: style, lints, documentation, the header check, unit tests, MPI tests on 1-4 ranks, p4est equality,
# then the installed CMake package with the C, C++ and Fortran examples (CTest).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
bash scripts/setup.sh
cargo fmt --check
cargo clippy --release --all-targets --quiet -- -D warnings
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --quiet
status=0
cargo test --release --no-fail-fast 2>&1 | tee target/test.log || status=1
bash scripts/test_cmake.sh target/cmake-test 2>&1 | tee -a target/test.log || status=1
# One closing line for the whole run (cargo's last line is the doc-test summary).
awk '/test result:/ { for (i = 1; i <= NF; i++) { if ($i ~ /^passed/) p += $(i-1); if ($i ~ /^failed/) f += $(i-1) } }
     /^mpi_(balance|mesh|faces): [0-9]+ passed/ { p += $2; f += $4 }
     /^cmake tests: / { p += $3; f += $5 }
     END { printf "tests: %d passed, %d failed\n", p, f }' target/test.log
exit $status
