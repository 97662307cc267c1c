#!/usr/bin/env bash
# laserline-spy, the lcm-spy that starts on Debian 12: its errors are one line; under a virtual
# display (Xvfb) it starts and finds the laserline types; run beside the daemon over UDP multicast
# in a private network namespace, the channel table lcm-spy shows (read back by SpyProbe in the
# same JVM) names our types with messages and none undecodable. Leaves a screenshot with the
# status channel's decoded fields at SCREENSHOT.
# Usage: test_spy.sh LASERLINED LASERLINE_SPY TYPES_JAR PROBE_JAR SCREENSHOT
set -euo pipefail
laserlined=$1 spy=$2 types=$3 probe=$4 screenshot=$5
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fail() {
  echo "test_spy: FAILED: $*" >&2
  exit 1
}
skip() {
  echo "[  SKIPPED ] test_spy: $*"
  exit 0
}
export LASERLINE_LCMTYPES_JAR=$types

# Errors: one line each, exit status 1.
expect_error() {
  local want=$1
  shift
  if "$@" >"$dir/out" 2>&1; then fail "$* succeeded"; fi
  [ "$(wc -l <"$dir/out")" -eq 1 ] || fail "$*: more than one line: $(cat "$dir/out")"
  grep -q -- "$want" "$dir/out" || fail "$*: '$(cat "$dir/out")' does not say '$want'"
}
expect_error "/nonexistent.jar: the laserline message types are not there" \
  env LASERLINE_LCMTYPES_JAR=/nonexistent.jar "$spy"
expect_error "no display (DISPLAY is not set)" env -u DISPLAY -u WAYLAND_DISPLAY "$spy"
"$spy" --help | grep -q "^usage: laserline-spy" || fail "--help"
"$spy" --version | grep -q "^laserline-spy [0-9]" || fail "--version"

command -v xvfb-run >/dev/null || skip "xvfb-run is not installed (package xvfb)"
command -v java >/dev/null || skip "java is not installed"
[ "$(id -u)" -eq 0 ] || skip "not root: no private network namespace for the multicast test"
unshare -n true 2>/dev/null || skip "cannot make a private network namespace here"
xvfb="xvfb-run -a -s '-screen 0 1280x800x24'"

# The wrapper itself starts lcm-spy (Debian's lcm-spy dies at once on OpenJDK 17's refusal of
# -Xincgc) and finds the types; still running after 4 s.
status=0
eval "$xvfb timeout 4 \"$spy\" --lcm-url=memq://" >"$dir/spy.out" 2>&1 || status=$?
[ "$status" -eq 124 ] || fail "laserline-spy ended (status $status) instead of running: $(cat "$dir/spy.out")"
found=$(sed -n 's/^Found \([0-9]*\) LCM types$/\1/p' "$dir/spy.out")
[ -n "$found" ] && [ "$found" -ge 4 ] || fail "lcm-spy found '$found' LCM types: $(cat "$dir/spy.out")"

cat >"$dir/config.yaml" <<YAML
camera: {backend: sim, frame_rate_hz: 20, sim: {seed: 3, distance_m: 1.0}}
calibration:
  camera: {width: 320, height: 256, fx: 350, fy: 350, cx: 159.5, cy: 127.5}
  laser: {baseline_m: 0.2, angle_deg: 80, sheet_width_m: 0.003}
lcm: {url: "udpm://239.255.76.67:7667?ttl=0", image_every_n: 10, status_period_s: 0.5}
YAML
classpath=$("$spy" --classpath):$probe
unshare -n bash -c "
  ip link set lo up multicast on && ip route add 224.0.0.0/4 dev lo || exit 3
  '$laserlined' --config '$dir/config.yaml' --duration 14 >'$dir/daemon.out' 2>&1 &
  sleep 1
  $xvfb java -Djava.net.preferIPv4Stack=true -cp '$classpath' SpyProbe \
    udpm://239.255.76.67:7667 8 '$screenshot' LASERLINE_STATUS >'$dir/probe.out' 2>&1
  probe=\$?
  wait
  exit \$probe
" || fail "SpyProbe: $(tail -5 "$dir/probe.out"); daemon: $(tail -2 "$dir/daemon.out")"
cat "$dir/probe.out"
for row in "LASERLINE_PROFILE	profile_t" "LASERLINE_STATUS	status_t" "LASERLINE_IMAGE	image_t"; do
  line=$(grep -P "^row\t$row\t" "$dir/probe.out") || fail "lcm-spy's table has no row '$row'"
  messages=$(cut -f4 <<<"$line")
  undecodable=$(cut -f9 <<<"$line")
  [ "$messages" -gt 0 ] || fail "'$row': $messages messages"
  [ "$undecodable" -eq 0 ] || fail "'$row': $undecodable undecodable"
done
[ -s "$screenshot" ] || fail "no screenshot at $screenshot"
echo "test_spy: lcm-spy decoded the profile, status and image channels; screenshot $screenshot"
