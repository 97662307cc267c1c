#!/usr/bin/env bash
# The desk tools on a real recording: laserlined writes a log (file:// LCM), then the Python log
# reader (generated Python types, no LCM module) and the example C++ subscriber read it back and
# must count exactly the profiles the daemon says it published; a damaged tail is reported and the
# rest still read.
# Usage: test_log_tools.sh LASERLINED EXAMPLE_SUBSCRIBER LOG_READER PYTHON_TYPES_DIR
set -euo pipefail
laserlined=$1 subscriber=$2 reader=$3 types=$4
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fail() {
  echo "test_log_tools: FAILED: $*" >&2
  exit 1
}

cat >"$dir/config.yaml" <<YAML
camera: {backend: sim, frame_rate_hz: 20, sim: {seed: 2, distance_m: 1.0}}
calibration:
  camera: {width: 320, height: 256, fx: 350, fy: 350, cx: 159.5, cy: 127.5}
  laser: {baseline_m: 0.2, angle_deg: 80, sheet_width_m: 0.003}
lcm: {url: "file://$dir/dive.lcmlog?mode=w", image_every_n: 10, image_compression: zlib,
      status_period_s: 0.5}
YAML
"$laserlined" --config "$dir/config.yaml" --duration 2 >"$dir/daemon.out" 2>&1 ||
  fail "laserlined: $(cat "$dir/daemon.out")"
published=$(sed -n 's/.* \([0-9]*\) profiles published.*/\1/p' "$dir/daemon.out")
[ -n "$published" ] && [ "$published" -gt 10 ] || fail "daemon published '$published' profiles"

python3 "$reader" "$dir/dive.lcmlog" --types "$types" --points "$dir/points.csv" >"$dir/reader.out" ||
  fail "reader: $(cat "$dir/reader.out")"
cat "$dir/reader.out"
grep -q "^LASERLINE_PROFILE: $published profiles, sequence 0\.\.$((published - 1)) (0 missing)" \
  "$dir/reader.out" || fail "reader did not count $published profiles"
grep -q "^LASERLINE_STATUS: .* messages; last: camera stopped, $published frames processed" \
  "$dir/reader.out" || fail "reader did not decode the last status"
grep -q "^LASERLINE_IMAGE: .* raw frames, last 160x128 (zlib)" "$dir/reader.out" ||
  fail "reader did not decode the raw frames"
rows=$(($(wc -l <"$dir/points.csv") - 1))
[ "$rows" -gt $((published * 100)) ] || fail "only $rows points in the CSV"

"$subscriber" "file://$dir/dive.lcmlog?speed=0" >"$dir/subscriber.out" 2>&1 ||
  fail "example subscriber: $(tail -3 "$dir/subscriber.out")"
[ "$(grep -c '^profile ' "$dir/subscriber.out")" -eq "$published" ] ||
  fail "example subscriber printed $(grep -c '^profile ' "$dir/subscriber.out") profiles"
grep -q '^status: camera stopped' "$dir/subscriber.out" || fail "example subscriber: no status"
echo "test_log_tools: $published profiles, $rows points; reader and example subscriber agree"

# A damaged tail: reported with where it is, everything before it still read, exit status 1.
head -c -100 "$dir/dive.lcmlog" >"$dir/damaged.lcmlog"
printf 'garbage' >>"$dir/damaged.lcmlog"
if python3 "$reader" "$dir/damaged.lcmlog" --types "$types" >"$dir/damaged.out" 2>&1; then
  fail "a damaged log must give exit status 1"
fi
grep -q "damaged tail: the last .* bytes (from byte [0-9]*) are not a complete event" \
  "$dir/damaged.out" || fail "no damaged-tail report: $(cat "$dir/damaged.out")"
grep -q "^LASERLINE_PROFILE: $((published - 1)) profiles\|^LASERLINE_PROFILE: $published profiles" \
  "$dir/damaged.out" || fail "profiles before the damage were not read: $(cat "$dir/damaged.out")"
echo "test_log_tools: damaged tail reported, the rest read"
