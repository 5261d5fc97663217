#!/usr/bin/env bash
# Interoperability check of the DJI Cloud API gateway with third-party MQTT software:
# Debian's mosquitto is the broker (password file; a plain listener for the cloud's
# services/events and a TLS listener, self-signed CA made here with openssl, for the
# DRC link), and paho-mqtt from PyPI plays the cloud (tests/interop/dji_cloud.py):
# authority, takeoff_to_point, drc_mode_enter over TLS, drone_control at 10 Hz,
# seq rules, heart_beat, emergency stop, drc_mode_exit, hostile payloads.
# The mesh is vehicle-sim + autopilot-link + shot-engine (the DJI flight tasks) +
# dji-gateway under `skymesh up`, without
# the embedded mqtt-broker. Uses the binaries in target/debug (cargo build --workspace
# first); installs mosquitto (apt-get) and paho-mqtt (pip, a venv if pip refuses).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

mosquitto_bin=$(command -v mosquitto || echo /usr/sbin/mosquitto)
if [ ! -x "$mosquitto_bin" ] || ! command -v mosquitto_passwd >/dev/null 2>&1; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends mosquitto >/dev/null
  mosquitto_bin=$(command -v mosquitto || echo /usr/sbin/mosquitto)
fi

# paho-mqtt 2 (the VERSION2 callback API): the system python if it has it or pip may
# install into it, else a venv kept in target/ (ignored by git, reused by later runs).
python=python3
has_paho() { "$1" -c 'import paho.mqtt.client as m; m.CallbackAPIVersion.VERSION2' 2>/dev/null; }
if ! has_paho "$python"; then
  if ! python3 -m pip install --quiet --disable-pip-version-check 'paho-mqtt>=2,<3' 2>/dev/null \
     || ! has_paho python3; then
    venv="$root/target/interop-venv"
    [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check 'paho-mqtt>=2,<3'
    python="$venv/bin/python"
  fi
fi

free_port() { python3 -c "import socket; s=socket.socket(); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])"; }
work=$(mktemp -d)
cleanup() {
  # The supervisor stops its services on SIGTERM (grace period), then exits.
  if [ -n "${mesh_pid:-}" ]; then
    kill -TERM "$mesh_pid" 2>/dev/null || true
    wait "$mesh_pid" 2>/dev/null || true
  fi
  if [ -n "${broker_pid:-}" ]; then
    kill -TERM "$broker_pid" 2>/dev/null || true
    wait "$broker_pid" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT
show_logs() {
  echo "---- mosquitto log ----"; cat "$work/mosquitto.log" 2>/dev/null || true
  echo "---- mesh log (supervisor and services) ----"; cat "$work/mesh.log" 2>/dev/null || true
}

plain_port=$(free_port)
tls_port=$(free_port)
sim_port=$(free_port)
user=skymesh-dock
password="interop-$$-$RANDOM"
sn="SKYMESH-INTEROP-$$"
home_lat=-35.363261
home_lon=149.165230
home_alt=584.0

# A CA and a server certificate for 127.0.0.1 (rustls checks the IP SAN).
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 \
  -subj "/CN=skymesh interop CA" -keyout "$work/ca.key" -out "$work/ca.pem" \
  -addext basicConstraints=critical,CA:TRUE -addext keyUsage=critical,keyCertSign,cRLSign \
  2>/dev/null
openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes \
  -subj "/CN=127.0.0.1" -keyout "$work/server.key" -out "$work/server.csr" 2>/dev/null
printf 'subjectAltName=IP:127.0.0.1,DNS:localhost\nbasicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\nextendedKeyUsage=serverAuth\n' \
  > "$work/server.ext"
openssl x509 -req -in "$work/server.csr" -CA "$work/ca.pem" -CAkey "$work/ca.key" \
  -CAcreateserial -days 2 -extfile "$work/server.ext" -out "$work/server.pem" 2>/dev/null

mosquitto_passwd -b -c "$work/passwd" "$user" "$password" 2>/dev/null
cat > "$work/mosquitto.conf" <<EOF
# One password file for both listeners; no anonymous clients.
per_listener_settings false
allow_anonymous false
password_file $work/passwd
# Started as root it would switch to the mosquitto user, who cannot read this temp dir.
user root
persistence false
log_dest stdout
log_type error
log_type warning
log_type notice
log_type information

listener $plain_port 127.0.0.1

listener $tls_port 127.0.0.1
cafile $work/ca.pem
certfile $work/server.pem
keyfile $work/server.key
EOF
"$mosquitto_bin" -c "$work/mosquitto.conf" > "$work/mosquitto.log" 2>&1 &
broker_pid=$!
for _ in $(seq 1 100); do
  (exec 3<>"/dev/tcp/127.0.0.1/$tls_port") 2>/dev/null && break
  sleep 0.05
done

# The mesh: no mqtt-broker service; the gateway's cloud broker is mosquitto (plain,
# with the password), and drc_mode_enter will name the TLS listener.
printf 'endpoint = "tcp:127.0.0.1:%s"\nhome_lat = %s\nhome_lon = %s\nhome_alt_msl = %s\n' \
  "$sim_port" "$home_lat" "$home_lon" "$home_alt" > "$work/vehicle-sim.toml"
printf 'connection = "tcpout:127.0.0.1:%s"\nvehicle_id = 1\nendpoints = []\n' \
  "$sim_port" > "$work/autopilot-link.toml"
printf 'vehicle_id = 1\nstate_file = "%s"\n' "$work/shot-engine-state.json" > "$work/shot-engine.toml"
cat > "$work/dji-gateway.toml" <<EOF
gateway_sn = "$sn"
vehicle_id = 1
[broker]
address = "127.0.0.1:$plain_port"
username = "$user"
password = "$password"
reconnect_initial_ms = 100
reconnect_max_ms = 1000
[drc]
ca_file = "$work/ca.pem"
connect_timeout_ms = 3000
EOF
cat > "$work/skymesh.toml" <<EOF
[supervisor]
metrics = "127.0.0.1:0"
ipc_config = "$root/deploy/iceoryx2.toml"
heartbeat_ms = 200
grace_period_ms = 3000

[[service]]
name = "vehicle-sim"
binary = "$root/target/debug/skymesh-vehicle-sim"
config = "vehicle-sim.toml"
critical = true

[[service]]
name = "autopilot-link"
binary = "$root/target/debug/skymesh-autopilot-link"
config = "autopilot-link.toml"
after = ["vehicle-sim"]
critical = true

# The DJI takeoff, fly-to and POI are flown by the shot engine's task runner.
[[service]]
name = "shot-engine"
binary = "$root/target/debug/skymesh-shot-engine"
config = "shot-engine.toml"
after = ["autopilot-link"]

[[service]]
name = "dji-gateway"
binary = "$root/target/debug/skymesh-dji-gateway"
config = "dji-gateway.toml"
after = ["autopilot-link", "shot-engine"]
EOF
SKYMESH_DOMAIN="interopdji$$" RUST_LOG=info target/debug/skymesh up --config "$work/skymesh.toml" \
  --metrics 127.0.0.1:0 --status-file "$work/metrics.addr" > "$work/mesh.log" 2>&1 &
mesh_pid=$!

if ! timeout 120 "$python" tests/interop/dji_cloud.py \
  --host 127.0.0.1 --port "$plain_port" --tls-port "$tls_port" --ca "$work/ca.pem" \
  --user "$user" --password "$password" --sn "$sn" \
  --home "$home_lat" "$home_lon" "$home_alt" \
  --status-file "$work/metrics.addr" --codes protocols/dji-proto/src/codes.rs; then
  show_logs
  exit 1
fi
