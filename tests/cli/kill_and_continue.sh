#!/bin/sh
# A run killed outright (kill -9) keeps its last map checkpoint (OUT/map); a run that continues
# it from the frame after the checkpoint ends with the map a single run makes: as many planes,
# none twice, the same recall.
# Usage: kill_and_continue.sh TESSERA RECORDING GROUND_TRUTH OUT_DIR KILL_AFTER_FRAME
set -u
tessera=$1 recording=$2 truth=$3 out=$4 kill_after=$5
rm -rf "$out" && mkdir -p "$out"
printf 'pipeline:\n  checkpoint_every_s: 1\n' >"$out/checkpoint.yaml"

# The last_frame of the run's saved map, or -1.
last_frame() {
  n=$(sed -n 's/^ *"last_frame": \([0-9]*\),*$/\1/p' "$1/map/session.json" 2>/dev/null)
  echo "${n:--1}"
}

"$tessera" run "$recording" --poses gt --config "$out/checkpoint.yaml" --out "$out/run" \
  >"$out/killed.log" 2>&1 &
pid=$!
i=0
while [ "$(last_frame "$out/run")" -lt "$kill_after" ]; do
  i=$((i + 1))
  [ $i -gt 3000 ] && { echo "FAIL: no checkpoint past frame $kill_after after 300 s"; exit 1; }
  kill -0 $pid 2>/dev/null || { cat "$out/killed.log"; echo "FAIL: the run ended first"; exit 1; }
  sleep 0.1
done
kill -9 $pid
wait $pid
resume=$(($(last_frame "$out/run") + 1))
echo "killed; the checkpoint holds frames up to $((resume - 1))"
[ -s "$out/run/report.json" ] && { echo "FAIL: the killed run got to its end"; exit 1; }

"$tessera" run "$recording" --poses gt --skip-frames "$resume" --continue "$out/run" \
  >"$out/continued.log" 2>&1 || { cat "$out/continued.log"; echo "FAIL: --continue failed"; exit 1; }
grep -q "continuing the map in" "$out/continued.log" || { echo "FAIL: not continued"; exit 1; }
"$tessera" run "$recording" --poses gt --no-save-map --out "$out/single" >"$out/single.log" 2>&1 \
  || { echo "FAIL: the single run failed"; exit 1; }
[ -d "$out/single/map" ] && { echo "FAIL: --no-save-map wrote a map"; exit 1; }

"$tessera" eval "$out/run" "$truth" >"$out/run.eval" 2>/dev/null
"$tessera" eval "$out/single" "$truth" >"$out/single.eval" 2>/dev/null
for key in planes_found plane_recall plane_precision duplicate_patches; do
  continued=$(sed -n "s/^$key: //p" "$out/run.eval")
  single=$(sed -n "s/^$key: //p" "$out/single.eval")
  echo "$key: continued $continued, single run $single"
  [ -n "$continued" ] && [ "$continued" = "$single" ] || { echo "FAIL: $key differs"; exit 1; }
done
echo "PASS"
