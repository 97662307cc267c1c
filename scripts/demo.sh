#!/usr/bin/env bash
# Installs the Debian packages, builds, and runs laserlined for ten seconds on the built-in
# simulated scanner (no hardware), with laserline-listen as a separate LCM subscriber. Both run
# in a private network namespace, so the multicast never leaves this machine. Prints what was
# published and writes an overlay PNG of the last raw frame with its detected points.
# Works as root or as a user with sudo; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh default

out_dir=${LASERLINE_DEMO_DIR:-$PWD/build/demo}
mkdir -p "$out_dir"
overlay="$out_dir/overlay.png"
bin=$PWD/build/default
# The subscriber asks for a large UDP receive buffer: raw frames are megabytes.
url='udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304'

# Root can make a network namespace directly; a user makes one inside a user namespace.
if [ "$(id -u)" -eq 0 ]; then ns=(unshare -n); else ns=(unshare -r -n); fi
"${ns[@]}" env BIN="$bin" URL="$url" OVERLAY="$overlay" sh -ec '
  ip link set lo up multicast on
  ip route add 224.0.0.0/4 dev lo
  "$BIN/tools/laserline-listen" --url "$URL" --overlay "$OVERLAY" --quiet 2 &
  listener=$!
  sleep 0.5
  "$BIN/daemon/laserlined" --duration 10
  wait "$listener"
'
