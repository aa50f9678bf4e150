#!/usr/bin/env bash
# The whole test suite: style, lints, documentation, the header check, unit tests, MPI tests on 1-4 ranks, p4est equality,
# then the installed CMake package with the C, C++ and Fortran examples (CTest).
# With CI=true or OCTMESH_REQUIRE_ORACLES=1 a test whose oracle (OpenFOAM, p4est, the shared models, meshio,
# valgrind, ...) is missing fails; otherwise it says "skipped: ..." and the closing line counts the skipped
# self-launching programs' tests (tests/common/mod.rs).
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
# The self-launching test programs (harness = false, tests/common/runner.rs) close with
# "NAME: P passed, F failed[, S skipped]".
awk '/test result:/ { for (i = 1; i <= NF; i++) { if ($i ~ /^passed/) p += $(i-1); if ($i ~ /^failed/) f += $(i-1) } }
     /^[a-z0-9_]+: [0-9]+ passed, [0-9]+ failed/ { p += $2; f += $4; if ($7 ~ /^skipped/) s += $6 }
     /^cmake tests: / { p += $3; f += $5 }
     END { printf "tests: %d passed, %d failed%s\n", p, f, s ? sprintf(", %d skipped", s) : "" }' target/test.log
exit $status
