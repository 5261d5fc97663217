#!/usr/bin/env bash
# The workspace's dependency rules (docs/architecture.md, "Crates and their rules"),
# checked on `cargo metadata` (normal dependencies; dev-dependencies of tests may
# reach anything):
#   - a gateway (services/*-gateway) depends on no engine (shot-engine, swarm-queue,
#     vision-pipeline): gateways translate, engines decide;
#   - an engine depends on no protocol crate (protocols/*): it knows no wire format;
#   - only autopilot-link (and vehicle-sim, the simulated aircraft) depend on the
#     MAVLink crates (`mavlink`, `mavlink-frame`).
# KNOWN lists the violations still being removed (issue 44): the check fails on any
# other violation, and on a KNOWN entry that no longer occurs (delete it then), so
# the list only shrinks.
set -euo pipefail
cd "$(dirname "$0")/.."
KNOWN=""
cargo metadata --format-version 1 --no-deps --offline 2>/dev/null \
  | KNOWN="$KNOWN" python3 -c '
import json, os, sys
meta = json.load(sys.stdin)
root = meta["workspace_root"] + "/"
kind = {}
for p in meta["packages"]:
    rel = p["manifest_path"][len(root):]
    if rel.startswith("protocols/"):
        kind[p["name"]] = "protocol"
    elif rel.startswith("services/") and p["name"].endswith("-gateway"):
        kind[p["name"]] = "gateway"
    elif p["name"] in ("skymesh-shot-engine", "skymesh-swarm-queue", "skymesh-vision-pipeline"):
        kind[p["name"]] = "engine"
mavlink_ok = {"skymesh-autopilot-link", "skymesh-vehicle-sim", "skymesh-e2e", "skymesh-benches"}
found = set()
for p in meta["packages"]:
    me = p["name"]
    for d in p["dependencies"]:
        if d["kind"] is not None:
            continue
        dep = d["name"]
        bad = (
            (kind.get(me) == "gateway" and kind.get(dep) == "engine")
            or (kind.get(me) == "engine" and kind.get(dep) == "protocol")
            or (dep in ("mavlink", "mavlink-frame") and me not in mavlink_ok and me != "mavlink-frame")
        )
        if bad:
            found.add(f"{me} -> {dep}")
known = {l.strip() for l in os.environ["KNOWN"].splitlines() if l.strip()}
new = sorted(found - known)
gone = sorted(known - found)
for v in sorted(found & known):
    print(f"known, being removed: {v}")
for v in new:
    print(f"VIOLATION: {v}")
for v in gone:
    print(f"no longer occurs, delete it from KNOWN in scripts/check-deps.sh: {v}")
if new or gone:
    sys.exit(1)
print(f"dependency rules hold ({len(found & known)} known exceptions left)")
'
