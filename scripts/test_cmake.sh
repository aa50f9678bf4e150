#!/usr/bin/env bash
# Tests of the CMake package: configure, build and install octmesh with CMake
# into build-cmake-test/prefix, then build every example as a separate
# consumer project (find_package and pkg-config) and run them with CTest
# (mpirun on 1, 2 and 4 ranks, the Poisson error falling with the level,
# valgrind on 1 rank). Ends with "cmake tests: N passed, M failed". With CI=true
# or OCTMESH_REQUIRE_ORACLES=1, a missing oracle (gfortran's Fortran library,
# valgrind) fails the configuration instead of leaving its tests out; the
# bunny comes from the shared folder ($OCTMESH_SHARED_DIR, else ../shared).
#   scripts/test_cmake.sh [BUILD_DIR]
set -uo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
root=$PWD
build=${1:-$root/build-cmake-test}
mkdir -p "$build"
build=$(cd "$build" && pwd)
prefix=$build/prefix
log=$build/test_cmake.log
: > "$log"

fail() {
  echo "$1 (see $log)"
  grep -A4 '^CMake Error' "$log" | head -n 20
  echo "cmake tests: 0 passed, 1 failed"
  exit 1
}

echo "== octmesh: configure, build, install into $prefix"
rm -rf "$prefix" "$build/tests"
cmake -S "$root" -B "$build/octmesh" >>"$log" 2>&1 || fail "configure failed"
cmake --build "$build/octmesh" -j 2 >>"$log" 2>&1 || fail "build failed"
cmake --install "$build/octmesh" --prefix "$prefix" >>"$log" 2>&1 || fail "install failed"
for f in lib/liboctmesh.so.0.1.0 lib/liboctmesh.so.0 lib/liboctmesh.so lib/liboctmesh.a \
         include/octmesh.h include/octmesh.hpp lib/cmake/octmesh/octmeshConfig.cmake \
         lib/cmake/octmesh/octmeshConfigVersion.cmake lib/pkgconfig/octmesh.pc; do
  [ -e "$prefix/$f" ] || fail "not installed: $f"
done
soname=$(readelf -d "$prefix/lib/liboctmesh.so.0.1.0" | sed -n 's/.*SONAME.*\[\(.*\)\]/\1/p')
[ "$soname" = liboctmesh.so.0 ] || fail "SONAME is '$soname', expected liboctmesh.so.0"

echo "== consumers and runs (ctest)"
cmake -S "$root/tests/cmake" -B "$build/tests" -DOCTMESH_PREFIX="$prefix" \
      -DOCTMESH_BUNNY="${OCTMESH_SHARED_DIR:-$root/../shared}/data/bunny.stl" >>"$log" 2>&1 \
  || fail "test configure failed"
(cd "$build/tests" && ctest --output-on-failure -j 2) 2>&1 | tee -a "$log"
grep -h '^POISSON ' "$build"/tests/Testing/Temporary/LastTest.log 2>/dev/null \
  | sed 's/^/  /' | sort -u || true
passed=$(grep -c 'Test *#[0-9]*: .*Passed' "$log")
failed=$(grep -Ec 'Test *#[0-9]*: .*(Failed|Not Run|Timeout|Exception)' "$log")
echo "cmake tests: $passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
