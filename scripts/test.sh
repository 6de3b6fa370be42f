#!/usr/bin/env bash
# Builds tessera and runs the whole test suite with ctest.
# Extra arguments go to CMake's configure step (e.g. -DTESSERA_SANITIZE=ON).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/build.sh "$@"
# --timeout: a test without a limit of its own fails after 15 minutes instead of hanging the run.
ctest --test-dir "${BUILD_DIR:-build}" --output-on-failure -j "$(nproc)" --timeout 900
