#!/usr/bin/env bash
# The whole test suite: style, lints, unit tests, MPI tests on 1-4 ranks, p4est equality.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
bash scripts/setup.sh
cargo fmt --check
cargo clippy --release --all-targets --quiet -- -D warnings
cargo test --release
