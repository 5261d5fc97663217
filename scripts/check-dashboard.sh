#!/usr/bin/env bash
# The Grafana dashboard and the alert rules against real data: starts the default
# mesh in its own domain (loopback ports), Debian's `prometheus` scraping it every
# second, flies a take-off through the GroundControl gateway and provokes a refusal
# by each gateway, then asks Prometheus (/api/v1/query) every PromQL expression of
# deploy/grafana/skymesh.json: each must return data, or the check fails naming the
# panel. The alert rules must pass `promtool check rules` and be loaded
# (/api/v1/rules). SKYMESH_DASHBOARD_KEEP=1 leaves mesh and Prometheus running for a
# look (Ctrl-C stops them).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${SKYMESH_BIN_DIR:-target/debug}  # where skymesh and the service binaries are
dashboard=deploy/grafana/skymesh.json
rules=deploy/prometheus/alerts.yml
domain="dash$$"
work=$(mktemp -d)
pid= prom_pid=
# On any failure: stop the mesh gracefully (the supervisor stops its services), and
# only then force it; SIGKILL first would orphan the services.
stop_mesh() {
  [ -n "${pid:-}" ] || return 0
  kill -TERM "$pid" 2>/dev/null || return 0
  for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || return 0; sleep 0.2; done
  kill -KILL "$pid" 2>/dev/null || true
}
stop_prometheus() {
  [ -n "${prom_pid:-}" ] || return 0
  kill -TERM "$prom_pid" 2>/dev/null || return 0
  wait "$prom_pid" 2>/dev/null || true
}
trap 'stop_prometheus; stop_mesh; rm -rf "$work"' EXIT

if ! command -v prometheus >/dev/null 2>&1; then
  apt-get update -qq &&
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends prometheus >/dev/null
fi
promtool check rules "$rules"

# The default configs (binaries are found next to `skymesh`), on free loopback ports
# so the check never collides with a mesh already running on this machine (as
# scripts/check-metrics.sh does).
free() { python3 -c "import socket; s=socket.socket(socket.AF_INET, socket.$1); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])"; }
port=$(free SOCK_STREAM)
cp deploy/*.toml "$work/"
cp -r deploy/animations "$work/"
sed -i "s#^endpoint = .*#endpoint = \"tcp:127.0.0.1:$port\"#" "$work/vehicle-sim.toml"
sed -i "s#^connection = .*#connection = \"tcpout:127.0.0.1:$port\"#" "$work/autopilot-link.toml"
solo_port=$(free SOCK_STREAM)
sed -i "s#^listen = .*#listen = \"127.0.0.1:$solo_port\"#" "$work/solo-gateway.toml"
sed -i "s#^follow_listen = .*#follow_listen = \"127.0.0.1:$(free SOCK_DGRAM)\"#" "$work/solo-gateway.toml"
imc_port=$(free SOCK_DGRAM)
sed -i "s#^listen = .*#listen = \"127.0.0.1:$imc_port\"#" "$work/imc-gateway.toml"
sed -i "s#^state_dir = .*#state_dir = \"$work/hardware\"#" "$work/hardware.toml"
mqtt_port=$(free SOCK_STREAM)
sed -i "s#^listen = .*#listen = \"127.0.0.1:$mqtt_port\"#" "$work/mqtt-broker.toml"
sed -i "s#^address = .*#address = \"127.0.0.1:$mqtt_port\"#" "$work/dji-gateway.toml"
gc_port=$(free SOCK_STREAM)
sed -i "s#^listen = .*#listen = \"127.0.0.1:$gc_port\"#" "$work/groundcontrol-gateway.toml"
sed -i "s#^broadcast_destinations = .*#broadcast_destinations = [\"127.0.0.1:$(free SOCK_DGRAM)\"]#" "$work/groundcontrol-gateway.toml"
digiview_port=$(free SOCK_STREAM)
sed -i "s#^listen = .*#listen = \"127.0.0.1:$digiview_port\"#" "$work/digiview-gateway.toml"

SKYMESH_DOMAIN=$domain "$bin/skymesh" up --config "$work/skymesh.toml" --metrics 127.0.0.1:0 \
  --status-file "$work/addr" > "$work/mesh.log" 2>&1 &
pid=$!
for _ in $(seq 1 300); do
  if [ -s "$work/addr" ] && curl -sf "http://$(cat "$work/addr")/metrics" -o "$work/metrics.txt" \
     && grep -q 'skymesh_autopilot_link_up{service="autopilot-link"} 1' "$work/metrics.txt"; then
    break
  fi
  kill -0 "$pid" 2>/dev/null || break
  sleep 0.2
done
if ! grep -q 'skymesh_autopilot_link_up{service="autopilot-link"} 1' "$work/metrics.txt" 2>/dev/null; then
  echo "mesh did not come up in time"; cat "$work/mesh.log"; exit 1
fi
echo "mesh up, metrics on $(cat "$work/addr")"

# Prometheus on a free loopback port, its data in the temp dir, scraping the mesh
# every second (rates over the dashboard's 1 min window need a few samples) with the
# shipped alert rules.
prom_port=$(free SOCK_STREAM)
prom="http://127.0.0.1:$prom_port"
# The shipped scrape config, pointed at this mesh.
sed -e "s#127.0.0.1:9464#$(cat "$work/addr")#" \
  -e "s#^\(  *\)\(scrape\|evaluation\)_interval: .*#\1\2_interval: 1s#" \
  -e "s#^\(  *\)- alerts.yml\$#\1- $PWD/$rules#" \
  deploy/prometheus/prometheus.yml > "$work/prometheus.yml"
grep -q "$(cat "$work/addr")" "$work/prometheus.yml" && grep -q "$PWD/$rules" "$work/prometheus.yml" &&
  ! grep -q 'interval: 5s' "$work/prometheus.yml" ||
  { echo "deploy/prometheus/prometheus.yml changed shape: adapt this script"; exit 1; }
promtool check config "$work/prometheus.yml" >/dev/null
prometheus --config.file="$work/prometheus.yml" --storage.tsdb.path="$work/tsdb" \
  --web.listen-address="127.0.0.1:$prom_port" > "$work/prometheus.log" 2>&1 &
prom_pid=$!
for _ in $(seq 1 100); do curl -sf "$prom/-/ready" >/dev/null && break; sleep 0.2; done
curl -sf "$prom/-/ready" >/dev/null || { echo "prometheus did not start"; cat "$work/prometheus.log"; exit 1; }
echo "prometheus $(prometheus --version 2>&1 | head -1 | awk '{print $3}') on $prom"

# Traffic for the panels that count events: a take-off through the GroundControl
# gateway (swarm queue → arbiter → autopilot), and one refused input per gateway:
# an unknown GroundControl record, an oversized Solo TLV, a DigiView frame with a
# bad checksum, an IMC message for another system.
"$bin/skymesh-gc" --server "127.0.0.1:$gc_port" --wait 1 takeoff 1
"$bin/skymesh-imc" --to "127.0.0.1:$imc_port" --dst 0x1234 --wait 0 heartbeat >/dev/null
python3 - "$gc_port" "$solo_port" "$digiview_port" <<'PY'
import socket, sys, time
gc, solo, digiview = (int(p) for p in sys.argv[1:])
for port, junk in ((gc, b"\xff" * 64), (solo, b"\xff" * 64), (digiview, b"\xff" * 88)):
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(junk)
        time.sleep(0.3)
PY
echo "scraping for ${SKYMESH_DASHBOARD_SCRAPE_S:-30} s"
sleep "${SKYMESH_DASHBOARD_SCRAPE_S:-30}"

# Every panel's queries, Grafana's variables replaced as Grafana would for "All".
python3 - "$dashboard" "$prom" <<'PY'
import json, sys, urllib.parse, urllib.request
path, prom = sys.argv[1:]
dashboard = json.load(open(path))
def panels(items):
    for p in items:
        yield p
        yield from panels(p.get("panels", []))
failed, checked = [], 0
for p in panels(dashboard["panels"]):
    if p["type"] == "row":
        continue
    if not p.get("targets"):
        failed.append(f"{p['title']}: no query")
    for t in p.get("targets", []):
        expr = t["expr"].replace("$instance", ".*").replace("$__rate_interval", "1m")
        if "$" in expr:
            failed.append(f"{p['title']}: unknown variable in {t['expr']}")
            continue
        url = prom + "/api/v1/query?" + urllib.parse.urlencode({"query": expr})
        try:
            answer = json.load(urllib.request.urlopen(url, timeout=10))
        except Exception as e:
            failed.append(f"{p['title']}: {expr}: {e}")
            continue
        checked += 1
        result = answer["data"]["result"]
        # NaN is what a gauge says before it knows (and a quantile of an empty
        # window): a panel of only NaN draws nothing.
        if answer["status"] != "success" or not result:
            failed.append(f"{p['title']}: no data for {expr}")
        elif all(r["value"][1] == "NaN" for r in result):
            failed.append(f"{p['title']}: only NaN for {expr}")
        elif any(k.startswith("exported_") for r in result for k in r["metric"]):
            failed.append(f"{p['title']}: a target label of prometheus.yml renamed a "
                          f"label of the mesh's own (exported_*) in {expr}")
        else:
            print(f"ok  {len(result):3} series  {p['title']}: {expr}")
for f in failed:
    print("FAILED", f)
print(f"{checked} queries of {sum(1 for p in panels(dashboard['panels']) if p['type'] != 'row')} panels")
sys.exit(1 if failed else 0)
PY

# The alert rules: all loaded, each evaluated without error.
python3 - "$rules" "$prom" <<'PY'
import json, re, sys, urllib.request
rules, prom = sys.argv[1:]
wanted = re.findall(r"^\s*-\s*alert:\s*(\S+)", open(rules).read(), re.M)
groups = json.load(urllib.request.urlopen(prom + "/api/v1/rules", timeout=10))["data"]["groups"]
loaded = {r["name"]: r for g in groups for r in g["rules"]}
bad = [n for n in wanted if n not in loaded]
bad += [f"{n}: {r.get('lastError')}" for n, r in loaded.items() if r.get("health") != "ok"]
for n in bad:
    print("FAILED alert rule", n)
print(f"{len(loaded)} alert rules loaded, {len(wanted)} in {rules}, firing: "
      + (", ".join(n for n, r in loaded.items() if r["state"] == "firing") or "none"))
sys.exit(1 if bad or not wanted else 0)
PY

if [ "${SKYMESH_DASHBOARD_KEEP:-0}" = 1 ]; then
  echo "mesh metrics on http://$(cat "$work/addr")/metrics, Prometheus on $prom (Ctrl-C stops)"
  wait "$pid"
fi
stop_prometheus
kill -TERM "$pid"
wait "$pid"
pid=
if ls /dev/shm | grep -q "^${domain}_"; then
  echo "shared memory left behind:"; ls /dev/shm | grep "^${domain}_"; exit 1
fi
echo "dashboard and alert rules checked against a live mesh"
