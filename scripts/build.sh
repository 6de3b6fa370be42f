#!/usr/bin/env bash
# Configures and builds tessera in Release into ./build (or $BUILD_DIR).
# Warnings are errors when TESSERA_WERROR=ON or when running under CI (CI=true).
# Extra arguments go to CMake's configure step.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${BUILD_DIR:-build}"
werror="${TESSERA_WERROR:-$([ "${CI:-}" = "true" ] && echo ON || echo OFF)}"
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" -DTESSERA_WERROR="$werror" "$@"
cmake --build "$build_dir" -j "$(nproc)"
