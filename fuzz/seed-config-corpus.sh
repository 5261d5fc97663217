#!/usr/bin/env bash
# Seeds the config_files corpus (fuzz/corpus/config_files, not in git) with every
# shipped deploy/*.toml behind its selector byte, the index of its service in
# SERVICES (fuzz_targets/config_files.rs). Run from anywhere; idempotent.
set -euo pipefail
cd "$(dirname "$0")"
services=(autopilot-link camera digiview-gateway dji-gateway groundcontrol-gateway hardware
  imc-gateway mqtt-broker shot-engine solo-gateway skymesh swarm-queue vehicle-sim
  vision-pipeline)
mkdir -p corpus/config_files
for i in "${!services[@]}"; do
  name=${services[$i]}
  { printf "\\x$(printf '%02x' "$i")"; cat "../deploy/$name.toml"; } > "corpus/config_files/seed-$name"
  # The same service's empty config (every default).
  printf "\\x$(printf '%02x' "$i")" > "corpus/config_files/seed-$name-empty"
done
echo "seeded corpus/config_files with ${#services[@]} deploy files"
