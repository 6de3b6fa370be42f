#!/bin/sh
# Ctrl-C during a run (a replay, or a live device): the run stops reading, finishes and
# exports the map, and exits 0. A second Ctrl-C aborts at once (status 130) and leaves the
# database readable.
# Usage: interrupt_run.sh TESSERA SOURCE OUT_DIR SOURCE_FRAMES STOP_AFTER [run options...]
# (the signal comes once stats.jsonl shows STOP_AFTER frames)
set -u
tessera=$1 recording=$2 out=$3 total=$4 stop_after=$5
shift 5
rm -rf "$out" && mkdir -p "$out"

# Waits until the run's stats.jsonl has $2 frame lines, or fails after 120 s.
wait_for_frames() {
  i=0
  while :; do
    n=$(grep -c '"type":"frame"' "$1/stats.jsonl" 2>/dev/null)
    [ "${n:-0}" -ge "$2" ] && return 0
    i=$((i + 1))
    [ $i -gt 1200 ] && { echo "FAIL: no $2 frames in $1/stats.jsonl after 120 s"; return 1; }
    sleep 0.1
  done
}

# Waits for the run $1 to exit (its status in $status), or fails after 120 s with its threads'
# stacks (when gdb is there) so that a hang is a failure that says where, not a stuck test.
wait_for_exit() {
  i=0
  while kill -0 "$1" 2>/dev/null; do
    i=$((i + 1))
    if [ $i -gt 1200 ]; then
      echo "FAIL: $2: still running 120 s after the interrupt"
      command -v gdb >/dev/null && gdb -p "$1" -batch -ex "thread apply all bt" 2>&1 | grep '^#'
      kill -KILL "$1"
      return 1
    fi
    sleep 0.1
  done
  wait "$1"
  status=$?
}

"$tessera" run "$recording" "$@" --out "$out/once" >"$out/once.log" 2>&1 &
pid=$!
wait_for_frames "$out/once" "$stop_after" || { kill -KILL $pid; exit 1; }
kill -INT $pid
wait_for_exit $pid "one Ctrl-C" || { cat "$out/once.log"; exit 1; }
cat "$out/once.log"
[ $status -eq 0 ] || { echo "FAIL: one Ctrl-C: exit status $status"; exit 1; }
for f in report.json mesh.ply patches.obj patches.json trajectory.txt textures.db; do
  [ -s "$out/once/$f" ] || { echo "FAIL: one Ctrl-C: no $f"; exit 1; }
done
grep -q '"stopped_on_request": true' "$out/once/report.json" || { echo "FAIL: not reported"; exit 1; }
frames=$(sed -n 's/^ *"frames": \([0-9]*\),$/\1/p' "$out/once/report.json")
echo "frames before the stop: $frames"
[ "$frames" -ge "$stop_after" ] && [ "$frames" -lt "$total" ] || { echo "FAIL: $frames frames"; exit 1; }

"$tessera" run "$recording" "$@" --out "$out/twice" >"$out/twice.log" 2>&1 &
pid=$!
wait_for_frames "$out/twice" "$stop_after" || { kill -KILL $pid; exit 1; }
kill -INT $pid
sleep 0.2
kill -INT $pid
wait_for_exit $pid "two Ctrl-C" || { cat "$out/twice.log"; exit 1; }
[ $status -eq 130 ] || { echo "FAIL: two Ctrl-C: exit status $status"; exit 1; }
"$tessera" db stats "$out/twice/textures.db" || { echo "FAIL: database unreadable"; exit 1; }
echo "PASS"
