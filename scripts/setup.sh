#!/usr/bin/env bash
# Installs what octmesh needs on Debian 12 (as root) and builds it in release mode.
# Safe to run again: it only installs packages that are missing.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(libopenmpi-dev openmpi-bin libclang-dev clang cmake gfortran libp4est-dev
          pkg-config make build-essential python3 python3-numpy python3-meshio python3-vtk9 python3-matplotlib valgrind
          openfoam calculix-ccx gmsh python3-gmsh python3-dolfinx
          libnetcdf-dev netcdf-bin python3-netcdf4 libcgns-dev cgns-convert)
missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
  [ -x "$HOME/.cargo/bin/cargo" ] || {
    echo "setup: installing the Rust toolchain with rustup"
    apt-get install -y -qq --no-install-recommends curl ca-certificates >/dev/null
    curl -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal --component rustfmt,clippy
  }
  export PATH="$HOME/.cargo/bin:$PATH"
fi

cargo build --release --quiet
make -s -C tools/p4est_ref
