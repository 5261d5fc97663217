#!/usr/bin/env bash
# Where a one-way sample's latency goes, iceoryx2 vs UDP: runs samples-bench (release)
# under a kernel trace with the benchmark's own clock and splits each message into
# sender work / kernel send / scheduler / return / receiver work (scripts/wake_stages.py).
# Needs perf with tracepoint access (root).
# usage: scripts/wake-stages.sh [RECEIVERS]   (default iox-blk,udp-blk)
#        SAMPLES_BENCH=path/to/samples-bench scripts/wake-stages.sh   (another build)
set -euo pipefail
cd "$(dirname "$0")/.."
only=${1:-iox-blk,udp-blk}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
bench=${SAMPLES_BENCH:-target/release/samples-bench}
[ -n "${SAMPLES_BENCH:-}" ] || cargo build --release -q -p skymesh-e2e --bin samples-bench
SAMPLES_BENCH_STAMPS="$work/stamps" perf record -q -k CLOCK_MONOTONIC -a -o "$work/perf.data" \
  -e syscalls:sys_enter_sendto,syscalls:sys_exit_epoll_wait,syscalls:sys_exit_recvfrom \
  -e sched:sched_waking,sched:sched_switch \
  -- "$bench" --only "$only"
# Phase names in run order: each rate runs the receivers in samples-bench's order.
order=$(for r in 100Hz 1kHz b2b; do for v in iox-blk udp-blk iox-tok udp-tok iox-ant; do
  case ",$only," in *",$v,"*) printf '%s-%s,' "$v" "$r";; esac; done; done)
perf script --ns -i "$work/perf.data" -F comm,pid,tid,cpu,time,event,trace 2>/dev/null |
  python3 scripts/wake_stages.py "$work/stamps" "${order%,}"
