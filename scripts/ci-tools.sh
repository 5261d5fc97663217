#!/usr/bin/env bash
# Installs what CI's later steps use and a fresh machine lacks, each only if missing:
# promtool, mosquitto, Chromium and chromedriver (apt-get, one call), pymavlink and
# paho-mqtt 2 (pip), cargo-deny, and for the fuzz step the nightly toolchain and
# cargo-fuzz. .ci/run starts it in the background during the test build: the
# downloads then overlap the compile instead of holding it up (they ran before it,
# mostly waiting on the network). The scripts that use a tool still install it
# themselves when run alone.
# cargo-fuzz is built unoptimised (`--debug`): it only drives cargo, and that halves
# its install (32 s against 59 s wall here). So is cargo-deny (the supply-chain
# step): half the CPU of an optimised install (3.4 against 6.9 CPU-minutes), for a
# check that takes ~9 s instead of ~3. It is pinned: a new release may change what
# deny.toml means.
set -uo pipefail
status=0

packages=()
# Debian's prometheus package brings promtool and the server (check-dashboard.sh).
if ! command -v promtool >/dev/null 2>&1 || ! command -v prometheus >/dev/null 2>&1; then
  packages+=(prometheus)
fi
if ! command -v mosquitto >/dev/null 2>&1 && [ ! -x /usr/sbin/mosquitto ]; then
  packages+=(mosquitto)
fi
# The web console's browser test (tests/tests/console.rs) drives headless Chromium.
if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then
  packages+=(chromium chromium-driver)
fi
if [ ${#packages[@]} -gt 0 ]; then
  apt-get update -qq &&
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      "${packages[@]}" >/dev/null || status=1
fi

# A pip that refuses the system python is not an error here: interop-dji.sh then
# makes its own venv, and the pymavlink scripts report their own failure.
python3 -c 'import pymavlink' 2>/dev/null ||
  python3 -m pip install --quiet --disable-pip-version-check pymavlink || true
python3 -c 'import paho.mqtt.client as m; m.CallbackAPIVersion.VERSION2' 2>/dev/null ||
  python3 -m pip install --quiet --disable-pip-version-check 'paho-mqtt>=2,<3' || true
# tests/tests/record.rs reads `skymesh record`'s MCAP files with a second implementation.
python3 -c 'import mcap.reader' 2>/dev/null ||
  python3 -m pip install --quiet --disable-pip-version-check mcap || true

if ! rustup toolchain list | grep -q '^nightly'; then
  rustup toolchain install nightly --profile minimal || true
fi
if ! command -v cargo-fuzz >/dev/null 2>&1; then
  cargo install cargo-fuzz --debug --locked --quiet || true
fi
if ! command -v cargo-deny >/dev/null 2>&1; then
  cargo install cargo-deny@0.20.2 --debug --locked --quiet || status=1
fi
exit "$status"
