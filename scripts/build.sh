#!/usr/bin/env bash
# Configures and builds tessera in Release into ./build (or $BUILD_DIR).
#   scripts/build.sh [-D...]          everything: the executable, the tests and the benchmarks
#                                     (a unity build in a new build directory)
#   scripts/build.sh --main [-D...]   only what `tessera run` needs: the executable and the
#                                     default recording (no tests, no benchmarks)
# Warnings are errors when TESSERA_WERROR=ON or when running under CI (CI=true).
# Other arguments go to CMake's configure step.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${BUILD_DIR:-build}"
werror="${TESSERA_WERROR:-$([ "${CI:-}" = "true" ] && echo ON || echo OFF)}"
if [ "${1:-}" = "--main" ]; then
  shift
  # The unity build compiles several sources per compiler run, so the heavy headers (Open3D,
  # OpenCV) are parsed fewer times. Should it ever fail, the build goes again file by file.
  main_build() {
    cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" -DTESSERA_WERROR=OFF \
      -DTESSERA_BUILD_TESTS=OFF -DTESSERA_BUILD_BENCH=OFF -DTESSERA_RENDER_DEFAULT_RECORDING=ON \
      -DCMAKE_UNITY_BUILD_BATCH_SIZE=8 "$@"
    cmake --build "$build_dir" -j "$(nproc)" --target tessera default_recording
  }
  main_build -DCMAKE_UNITY_BUILD=ON "$@" || main_build -DCMAKE_UNITY_BUILD=OFF "$@"
  exit
fi
full_build() {
  cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" \
    -DTESSERA_WERROR="$werror" -DTESSERA_BUILD_TESTS=ON -DTESSERA_BUILD_BENCH=ON "$@"
  cmake --build "$build_dir" -j "$(nproc)"
}
if [ -f "$build_dir/CMakeCache.txt" ]; then
  # A build directory keeps the choice it was configured with: file by file, a developer's
  # rebuild after a change compiles one source, not the eight merged with it.
  full_build "$@"
else
  # From scratch, a unity build takes about half the time (11 instead of 23 minutes on two
  # cores). Should it fail, the build goes again file by file.
  full_build -DCMAKE_UNITY_BUILD=ON -DCMAKE_UNITY_BUILD_BATCH_SIZE=8 "$@" || {
    echo "build.sh: the unity build failed; building again file by file" >&2
    full_build -DCMAKE_UNITY_BUILD=OFF "$@"
  }
fi
