#!/usr/bin/env bash
# Fuzzes the STL reader and the C API with cargo-fuzz (libFuzzer, nightly Rust) for a bounded time.
#
#   bash scripts/fuzz.sh [SECONDS] [TARGET...]    # default: 60 s for each of the targets stl and api
#
# Each target starts from its committed corpus fuzz/regressions/TARGET (read-only seeds) and keeps what it
# learns in fuzz/corpus/TARGET (not committed). A crash, leak, timeout or out-of-memory input found by libFuzzer
# (fuzz/artifacts/TARGET/) is copied into fuzz/regressions/TARGET/, where tests/fuzz_regression.rs replays it on
# stable Rust: fix the library, then commit the input with the fix. Prints the executions of each run and exits
# non-zero if anything was found. Installs cargo-fuzz when it is missing (needs the nightly toolchain).
set -uo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
secs=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(stl api)

if ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz.sh: the nightly toolchain is needed (rustup toolchain install nightly)" >&2
    exit 2
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked || exit 2
fi

# MPI is never finalised (one initialisation serves every input), so Open MPI's allocations are still there at
# exit; libFuzzer checks each input for leaks, which is what matters.
supp=$(mktemp)
trap 'rm -f "$supp"' EXIT
printf 'leak:libmpi\nleak:libopen-pal\nleak:libopen-rte\nleak:libhwloc\nleak:libevent\nleak:libpmix\n' >"$supp"
export LSAN_OPTIONS="suppressions=$supp:print_suppressions=0:leak_check_at_exit=0"
# Open MPI's own SIGABRT/SIGSEGV handlers would exit before libFuzzer saves the crashing input.
export OMPI_MCA_opal_signal=""

found=0
cd fuzz
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t" "artifacts/$t"
    before=$(ls "artifacts/$t" | sort)
    log="artifacts/$t.log"
    echo "== fuzz target $t for $secs s"
    cargo +nightly fuzz run "$t" "corpus/$t" "regressions/$t" -- \
        -max_total_time="$secs" -timeout=20 -rss_limit_mb=4096 -print_final_stats=1 >"$log" 2>&1
    status=$?
    grep -E '^(#[0-9]+[[:space:]]+(INITED|DONE)|==[0-9]+==ERROR|SUMMARY|Test unit written|thread .* panicked)' "$log"
    if [ $status -ne 0 ]; then
        echo "$t: the fuzzer stopped with status $status (see fuzz/$log)"
        found=1
    fi
    grep -E '^stat::number_of_executed_units' "$log" | sed "s/^/$t: /"
    for a in $(ls "artifacts/$t" | sort); do
        if ! grep -qx "$a" <<<"$before"; then
            cp "artifacts/$t/$a" "regressions/$t/$a"
            echo "$t: new input regressions/$t/$a"
            found=1
        fi
    done
done
exit $found
