#!/usr/bin/env bash
# Checks that a refactoring kept behaviour: replays the default recording and the BundleFusion
# apartment (from ../shared/data, skipped when absent) and compares what each run decided
# (scripts/run_fingerprint.py: the texture database's textures and instances, report.json's
# figures but timings) with the fingerprints in tests/reference/.
#   scripts/check_unchanged.sh [TESSERA]      compare (TESSERA: build/tessera by default)
#   scripts/check_unchanged.sh --save [TESSERA]   write new reference fingerprints
# A change meant to alter the map saves new fingerprints and says so in its commit.
set -euo pipefail
cd "$(dirname "$0")/.."
save=false
if [ "${1:-}" = "--save" ]; then save=true; shift; fi
tessera="${1:-build/tessera}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
status=0

check() {  # NAME, then tessera run's arguments
  local name="$1"; shift
  echo "check_unchanged: $name" >&2
  "$tessera" run --quiet --log-level warn "$@" --out "$work/$name"
  python3 scripts/run_fingerprint.py "$work/$name" > "$work/$name.fingerprint"
  local reference="tests/reference/$name.fingerprint"
  if $save; then
    cp "$work/$name.fingerprint" "$reference"
  elif ! diff -u "$reference" "$work/$name.fingerprint"; then
    echo "check_unchanged: $name differs from $reference" >&2
    status=1
  fi
}

check office recordings/office.oni
bundlefusion=../shared/data/rgbd/bundlefusion_apt0_kf219
if [ -d "$bundlefusion" ]; then
  check bundlefusion_apt0_kf219 "$bundlefusion" --poses gt --depth-scale 1000
else
  echo "check_unchanged: $bundlefusion is absent (the shared data is not beside this clone): skipped" >&2
fi
[ "$status" -eq 0 ] && echo "check_unchanged: the same decisions and figures as tests/reference/" >&2
exit "$status"
