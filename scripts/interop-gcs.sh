#!/usr/bin/env bash
# Interoperability check: pymavlink (installed from PyPI) acts as a ground station
# through autopilot-link's MAVLink router (a `udpin` endpoint), vehicle-sim behind it.
# Uses the binaries in target/debug (cargo build --workspace first).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -c 'import pymavlink' 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check pymavlink
free_port() { python3 -c "import socket; s=socket.socket(socket.AF_INET, socket.$1); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])"; }
sim_port=$(free_port SOCK_STREAM)
gcs_port=$(free_port SOCK_DGRAM)
work=$(mktemp -d)
export SKYMESH_DOMAIN="interopgcs$$"
# No supervisor here to remove the domain's shared memory after its processes:
# the trap does (iceoryx2's node files, the topics' event counts).
trap 'kill "${link_pid:-0}" "${sim_pid:-0}" 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$work" /dev/shm/"$SKYMESH_DOMAIN"_* /dev/shm/"$SKYMESH_DOMAIN".*' EXIT
printf 'endpoint = "tcp:127.0.0.1:%s"\n' "$sim_port" > "$work/sim.toml"
printf 'connection = "tcpout:127.0.0.1:%s"\nendpoints = ["udpin:127.0.0.1:%s"]\n' "$sim_port" "$gcs_port" > "$work/link.toml"
target/debug/skymesh-vehicle-sim --config "$work/sim.toml" > "$work/sim.log" 2>&1 &
sim_pid=$!
target/debug/skymesh-autopilot-link --config "$work/link.toml" > "$work/link.log" 2>&1 &
link_pid=$!
if ! timeout 120 python3 tests/interop/pymavlink_gcs.py "$gcs_port"; then
  echo "---- autopilot-link log ----"; cat "$work/link.log"
  echo "---- vehicle-sim log ----"; cat "$work/sim.log"
  exit 1
fi
