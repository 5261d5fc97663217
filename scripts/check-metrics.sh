#!/usr/bin/env bash
# Starts the default mesh in its own domain, scrapes /metrics once every service has
# reported, validates the scrape with `promtool check metrics`, then stops the mesh
# and checks it left nothing behind.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/debug
domain="ci$$"
work=$(mktemp -d)
# On any failure: stop the mesh gracefully (the supervisor stops its services), and
# only then force it; SIGKILL first would orphan the services.
stop_mesh() {
  [ -n "${pid:-}" ] || return 0
  kill -TERM "$pid" 2>/dev/null || return 0
  for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || return 0; sleep 0.2; done
  kill -KILL "$pid" 2>/dev/null || true
}
trap 'stop_mesh; rm -rf "$work"' EXIT

# The default configs (binaries are found next to `skymesh`), but on a free MAVLink
# port so CI never collides with a mesh already running on this machine.
free() { python3 -c "import socket; s=socket.socket(socket.AF_INET, socket.$1); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])"; }
port=$(free SOCK_STREAM)
cp deploy/*.toml "$work/"
cp -r deploy/animations "$work/"
sed -i "s#^endpoint = .*#endpoint = \"tcp:127.0.0.1:$port\"#" "$work/vehicle-sim.toml"
sed -i "s#^connection = .*#connection = \"tcpout:127.0.0.1:$port\"#" "$work/autopilot-link.toml"
# The Solo gateway's app and follow-stream ports too.
sed -i "s#^listen = .*#listen = \"127.0.0.1:$(free SOCK_STREAM)\"#" "$work/solo-gateway.toml"
sed -i "s#^follow_listen = .*#follow_listen = \"127.0.0.1:$(free SOCK_DGRAM)\"#" "$work/solo-gateway.toml"
# The IMC gateway's UDP port; the hardware service's simulated devices in the temp dir.
sed -i "s#^listen = .*#listen = \"127.0.0.1:$(free SOCK_DGRAM)\"#" "$work/imc-gateway.toml"
sed -i "s#^state_dir = .*#state_dir = \"$work/hardware\"#" "$work/hardware.toml"
# The MQTT broker's port, and the DJI gateway pointed at it.
mqtt_port=$(free SOCK_STREAM)
sed -i "s#^listen = .*#listen = \"127.0.0.1:$mqtt_port\"#" "$work/mqtt-broker.toml"
sed -i "s#^address = .*#address = \"127.0.0.1:$mqtt_port\"#" "$work/dji-gateway.toml"
# The GroundControl state server and pose broadcast destination.
sed -i "s#^listen = .*#listen = \"127.0.0.1:$(free SOCK_STREAM)\"#" "$work/groundcontrol-gateway.toml"
sed -i "s#^broadcast_destinations = .*#broadcast_destinations = [\"127.0.0.1:$(free SOCK_DGRAM)\"]#" "$work/groundcontrol-gateway.toml"

SKYMESH_DOMAIN=$domain "$bin/skymesh" up --config "$work/skymesh.toml" --metrics 127.0.0.1:0 \
  --status-file "$work/addr" > "$work/out.log" 2>&1 &
pid=$!
for _ in $(seq 1 300); do
  if [ -s "$work/addr" ] && curl -sf "http://$(cat "$work/addr")/metrics" -o "$work/metrics.txt" \
     && grep -q 'skymesh_topic_samples_received_total' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="autopilot-link"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_solo_clients_connected' "$work/metrics.txt" \
     && grep -q 'skymesh_shot_current' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="imc-gateway"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="hardware"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="swarm-queue"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="groundcontrol-gateway"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="mqtt-broker"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_service_up{service="dji-gateway"} 1' "$work/metrics.txt" \
     && grep -q 'skymesh_dji_broker_connected{service="dji-gateway"} 1' "$work/metrics.txt"; then
    break
  fi
  sleep 0.2
done
if ! grep -q 'skymesh_topic_samples_published_total' "$work/metrics.txt" 2>/dev/null; then
  echo "mesh did not report metrics in time"; cat "$work/out.log"; exit 1
fi
echo "scraped $(wc -l < "$work/metrics.txt") lines from $(cat "$work/addr")"
promtool check metrics < "$work/metrics.txt"
kill -TERM "$pid"
wait "$pid"
if ls /dev/shm | grep -q "^${domain}_"; then
  echo "shared memory left behind:"; ls /dev/shm | grep "^${domain}_"; exit 1
fi
echo "mesh stopped cleanly"
