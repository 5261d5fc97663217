#!/usr/bin/env bash
# Every issue-10 measurement once, back to back, with one release build: the
# snapshot behind the "Targets" table of docs/benchmarks.md.
# Each program runs its baseline in the same run; this only runs them in a row and
# keeps their output. ~20 minutes here, plus the build.
#
# usage: scripts/bench-snapshot.sh [OUT_DIR]    (default target/bench-snapshot)
#        SKIP_BUILD=1 scripts/bench-snapshot.sh  (the release binaries as they are)
#
# The real-time runs (frames with the receiver on its own core, the Solo and DRC
# paths as shipped) need SCHED_FIFO: root, CAP_SYS_NICE or `ulimit -r`. Without it
# they run with normal scheduling and the log says so.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/bench-snapshot}
mkdir -p "$out"
[ -n "${SKIP_BUILD:-}" ] || cargo build --release -q --workspace --bins
b=target/release
rt=()
frames_rt=()
if chrt -f 10 true 2>/dev/null; then
  rt=(--realtime 20)
  frames_rt=(env FRAMES_BENCH_RX_CPU=1 FRAMES_BENCH_RX_RT=10 taskset -c 0)
else
  echo "no SCHED_FIFO here: the real-time runs use normal scheduling" | tee "$out/NOTE"
fi
run() {
  local name=$1
  shift
  echo "=== $name $(date +%T)"
  "$@" >"$out/$name.log" 2>&1 || echo "    $name failed: see $out/$name.log"
}
# Tails need messages: at the programs' default counts a p99 is the 5th-worst of
# 450 messages (100 Hz) or the 2nd-worst of 190 frames, and moved by a handful of
# host events. Ten times the samples and twice the frames give p99s of 50 and 4.
run samples "$b/samples-bench" 10 --interleave --only iox-tok,udp-tok,busy,block,udp
run samples-2 "$b/samples-bench" 10 --interleave --only iox-tok,udp-tok
run fanout "$b/fanout-bench"
run frames "$b/frames-bench" 400
run frames-1080p-rt env FRAMES_BENCH_ONLY=1920 "${frames_rt[@]}" "$b/frames-bench" 400
run telemetry "$b/telemetry-bench" --samples 3000
run solo "$b/solo-bench" --rounds 40 "${rt[@]}" --vision
run dji "$b/dji-bench" --commands 300 "${rt[@]}" --vision
run mesh "$b/mesh-bench" --default-mesh --kills 3 --window-secs 30 --settle-secs 8
if command -v gcc >/dev/null; then
  gcc -O2 -o "$out/idle-floor" scripts/idle-floor.c
  run idle-floor "$out/idle-floor" 30
  run idle-floor-rest "$out/idle-floor" 30 rest
fi
echo "=== done $(date +%T): $out"
