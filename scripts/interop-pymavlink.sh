#!/usr/bin/env bash
# Interoperability check: pymavlink (installed from PyPI) flies vehicle-sim.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -c 'import pymavlink' 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check pymavlink
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
work=$(mktemp -d)
domain="interop$$"
# No supervisor here to remove the domain's shared memory after the simulator: the
# trap does.
trap 'kill "${pid:-0}" 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$work" /dev/shm/"$domain"_* /dev/shm/"$domain".*' EXIT
printf 'endpoint = "tcp:127.0.0.1:%s"\n' "$port" > "$work/sim.toml"
SKYMESH_DOMAIN="$domain" target/debug/skymesh-vehicle-sim --config "$work/sim.toml" > "$work/sim.log" 2>&1 &
pid=$!
for _ in $(seq 1 100); do
  (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && break
  sleep 0.1
done
if ! timeout 120 python3 tests/interop/pymavlink_vehicle_sim.py "$port"; then
  echo "---- vehicle-sim log ----"; cat "$work/sim.log"; exit 1
fi
