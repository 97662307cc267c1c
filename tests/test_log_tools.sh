#!/usr/bin/env bash
# The desk tools on a real recording: laserlined writes a log (file:// LCM), then the Python log
# reader (generated Python types, no LCM module) and the example C++ subscriber read it back and
# must count exactly the profiles the daemon says it published; a damaged tail is reported and the
# rest still read.
# Damaged and hostile logs: every reader goes on past damage, says where and how much, exits 1,
# never crashes or prints a traceback.
# Usage: test_log_tools.sh LASERLINED EXAMPLE_SUBSCRIBER LOG_READER PYTHON_TYPES_DIR LISTEN
set -euo pipefail
laserlined=$1 subscriber=$2 reader=$3 types=$4 listen=$5
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
grep -q "the log ends inside an event or in damage: the last .* bytes (from byte [0-9]*) are not a complete event" \
  "$dir/damaged.out" || fail "no damaged-tail report: $(cat "$dir/damaged.out")"
grep -q "^LASERLINE_PROFILE: $((published - 1)) profiles\|^LASERLINE_PROFILE: $published profiles" \
  "$dir/damaged.out" || fail "profiles before the damage were not read: $(cat "$dir/damaged.out")"
echo "test_log_tools: damaged tail reported, the rest read"

# Damage in the middle: the readers resume at the next whole event and say what they skipped.
# 3000 bytes overwritten from the 25th event's sync word on.
at=$(python3 - "$dir/dive.lcmlog" <<'PY'
import struct, sys
blob, pos = open(sys.argv[1], "rb").read(), 0
for _ in range(25):
    pos += 28 + sum(struct.unpack_from(">II", blob, pos + 20))
print(pos)
PY
)
cp "$dir/dive.lcmlog" "$dir/middle.lcmlog"
printf '%*s' 3000 '' | dd of="$dir/middle.lcmlog" bs=1 seek="$at" conv=notrunc status=none
for tool in reader listen; do
  if [ $tool = reader ]; then
    cmd=(python3 "$reader" "$dir/middle.lcmlog" --types "$types")
  else
    cmd=("$listen" --url "file://$dir/middle.lcmlog")
  fi
  status=0
  "${cmd[@]}" >"$dir/middle.out" 2>&1 || status=$?
  [ $status -eq 1 ] || fail "$tool: damage in the middle gave exit status $status: $(cat "$dir/middle.out")"
  grep -q "are damaged ([0-9]* bytes, [0-9]* records); skipped, reading resumes at event" \
    "$dir/middle.out" || fail "$tool: no report of the damage: $(cat "$dir/middle.out")"
  grep -q "1 damaged region ([0-9]* records, [0-9]* bytes skipped, the first at byte " \
    "$dir/middle.out" || fail "$tool: no summary of the damage: $(cat "$dir/middle.out")"
  got=$(sed -n 's/^LASERLINE_PROFILE: \([0-9]*\) profiles.*/\1/p; s/^  profiles: \([0-9]*\) .*/\1/p' \
    "$dir/middle.out")
  [ -n "$got" ] && [ "$got" -ge $((published * 3 / 4)) ] ||
    fail "$tool: only '$got' of $published profiles read past the damage: $(cat "$dir/middle.out")"
done
echo "test_log_tools: damage in the middle skipped and reported, $got profiles read"

# Damage between every two events: every event still read, the damage reported in a few lines
# and summed up, not a line per region.
python3 - "$dir/dive.lcmlog" "$dir/everywhere.lcmlog" <<'PY'
import struct, sys
blob, out, pos = open(sys.argv[1], "rb").read(), bytearray(), 0
while pos + 28 <= len(blob):
    end = pos + 28 + sum(struct.unpack_from(">II", blob, pos + 20))
    out += blob[pos:end] + b"garbage"
    pos = end
open(sys.argv[2], "wb").write(out)
PY
events=$(python3 "$reader" "$dir/dive.lcmlog" --types "$types" | sed -n 's/.*: \([0-9]*\) events over.*/\1/p')
for tool in reader listen; do
  if [ $tool = reader ]; then
    cmd=(python3 "$reader" "$dir/everywhere.lcmlog" --types "$types")
  else
    cmd=("$listen" --url "file://$dir/everywhere.lcmlog")
  fi
  status=0
  "${cmd[@]}" >"$dir/everywhere.out" 2>"$dir/everywhere.err" || status=$?
  [ $status -eq 1 ] || fail "$tool: exit status $status: $(cat "$dir/everywhere.err")"
  grep -q ": $events damaged regions ($events records, $((events * 7)) bytes skipped, the first at" \
    "$dir/everywhere.err" || fail "$tool: no summary of $events regions: $(cat "$dir/everywhere.err")"
  [ "$(wc -l <"$dir/everywhere.err")" -le 25 ] ||
    fail "$tool: a line per damaged region: $(wc -l <"$dir/everywhere.err") lines"
  grep -q "$published profiles\|profiles: $published " "$dir/everywhere.out" ||
    fail "$tool: not every profile read: $(cat "$dir/everywhere.out")"
done
echo "test_log_tools: damage between all $events events: every event read, $events regions summed up"

# A corrupt size field (an image's size one less than its bytes) and a hostile status (string
# length -1, which made lcm-gen's C++ decode throw std::length_error): refused in one line each.
python3 - "$dir/dive.lcmlog" "$dir/hostile.lcmlog" <<'PY'
import struct, sys
blob = open(sys.argv[1], "rb").read()
out, pos, patched = bytearray(), 0, set()
while pos + 28 <= len(blob):
    _, _, _, clen, dlen = struct.unpack_from(">IqqII", blob, pos)
    end = pos + 28 + clen + dlen
    event = bytearray(blob[pos:end])
    channel = bytes(event[28:28 + clen])
    data = 28 + clen
    if channel == b"LASERLINE_IMAGE" and "image" not in patched:
        size = struct.unpack_from(">i", event, data + 59)[0]
        struct.pack_into(">i", event, data + 59, size - 1)
        patched.add("image")
    elif channel == b"LASERLINE_STATUS" and "status" not in patched:
        struct.pack_into(">i", event, data + 24, -1)  # camera_backend's length
        patched.add("status")
    out += event
    pos = end
open(sys.argv[2], "wb").write(out)
assert patched == {"image", "status"}, patched
PY
status=0
python3 "$reader" "$dir/hostile.lcmlog" --types "$types" >"$dir/hostile.out" 2>&1 || status=$?
[ $status -eq 1 ] || fail "reader: hostile log gave exit status $status: $(cat "$dir/hostile.out")"
grep -q "on LASERLINE_IMAGE: its size fields do not match its [0-9]* bytes" "$dir/hostile.out" ||
  fail "reader accepted a corrupt size field: $(cat "$dir/hostile.out")"
! grep -q Traceback "$dir/hostile.out" || fail "reader: $(cat "$dir/hostile.out")"
status=0
"$listen" --url "file://$dir/hostile.lcmlog" >"$dir/hostile.out" 2>&1 || status=$?
[ $status -eq 1 ] || fail "listen: hostile log gave exit status $status: $(cat "$dir/hostile.out")"
grep -q "on LASERLINE_STATUS: camera_backend at byte 24: length -1 outside 1..257; skipped" \
  "$dir/hostile.out" || fail "listen: no report of the hostile status: $(cat "$dir/hostile.out")"
grep -q "on LASERLINE_IMAGE: 1 bytes after the end of the laserline.image_t" "$dir/hostile.out" ||
  fail "listen: no report of the corrupt size: $(cat "$dir/hostile.out")"
status=0
"$subscriber" "file://$dir/hostile.lcmlog?speed=0" >"$dir/hostile.out" 2>&1 || status=$?
[ $status -eq 0 ] || fail "example subscriber: exit status $status: $(tail -3 "$dir/hostile.out")"
grep -q "LASERLINE_STATUS: camera_backend at byte 24: length -1" "$dir/hostile.out" ||
  fail "example subscriber: no report of the hostile status: $(tail -3 "$dir/hostile.out")"
echo "test_log_tools: corrupt size field and hostile string refused in one line"

# 30 logs damaged at random: a length field of a message (a string's, num_points, an image's
# size) set to a hostile value, bytes overwritten, cut out or doubled, the end cut. No traceback,
# no crash, exit status 0 or 1.
for seed in $(seq 1 30); do
  python3 - "$dir/dive.lcmlog" "$dir/random.lcmlog" "$seed" <<'PY'
import random, struct, sys
blob = bytearray(open(sys.argv[1], "rb").read())
rng = random.Random(int(sys.argv[3]))
fields, pos = [], []  # offsets of length fields in the messages
at = 0
while at + 28 <= len(blob):
    clen, dlen = struct.unpack_from(">II", blob, at + 20)
    channel, data = bytes(blob[at + 28:at + 28 + clen]), at + 28 + clen
    if channel == b"LASERLINE_PROFILE":
        detector = struct.unpack_from(">i", blob, data + 41)[0]
        fields += [data + 41, data + 41 + 4 + detector + 58]
    elif channel == b"LASERLINE_STATUS":
        fields.append(data + 24)
    elif channel == b"LASERLINE_IMAGE":
        fields.append(data + 59)
    at = data + dlen
for n in range(rng.randint(2, 8)):
    kind = 0 if n < 2 else rng.randrange(4)
    if kind == 0:
        struct.pack_into(">i", blob, rng.choice(fields),
                         rng.choice([-1, 0, 0x7fffffff, rng.randrange(-2**31, 2**31)]))
        continue
    at = rng.randrange(len(blob))
    if kind == 1:
        for i in range(at, min(len(blob), at + rng.randint(1, 64))):
            blob[i] = rng.randrange(256)
    elif kind == 2:
        blob = blob[:at] + blob[at + rng.randint(1, 500):]
    else:
        blob = blob[:at] + blob[at:at + rng.randint(1, 500)] + blob[at:]
if rng.random() < 0.3:
    blob = blob[:rng.randrange(len(blob))]
open(sys.argv[2], "wb").write(blob)
PY
  for tool in reader listen; do
    status=0
    if [ $tool = reader ]; then
      python3 "$reader" "$dir/random.lcmlog" --types "$types" >"$dir/random.out" 2>&1 || status=$?
    else
      "$listen" --url "file://$dir/random.lcmlog" >"$dir/random.out" 2>&1 || status=$?
    fi
    [ $status -le 1 ] || fail "$tool: damaged log $seed: exit status $status: $(tail -5 "$dir/random.out")"
    ! grep -q Traceback "$dir/random.out" || fail "$tool: damaged log $seed: $(cat "$dir/random.out")"
  done
done
echo "test_log_tools: 30 randomly damaged logs read without a crash or a traceback"

# Files that are no log: one line each naming the file, exit status 1, no traceback.
: >"$dir/empty.lcmlog"
for bad in "$dir/nonexistent.lcmlog:No such file or directory" "$dir:Is a directory" \
  "$dir/config.yaml:not an LCM log (none of its" "$dir/empty.lcmlog:empty file, not an LCM log"; do
  path=${bad%%:*} reason=${bad#*:}
  status=0
  python3 "$reader" "$path" --types "$types" >"$dir/bad.out" 2>&1 || status=$?
  [ $status -eq 1 ] && [ "$(wc -l <"$dir/bad.out")" -eq 1 ] &&
    grep -q "^laserline-log-reader: $path: $reason" "$dir/bad.out" ||
    fail "reader on $path: exit status $status: $(cat "$dir/bad.out")"
done
echo "test_log_tools: a missing file, a directory, an empty file and a YAML file: one line each"

# Two daemons on the same channels (their logs one after the other): told apart by instance id.
sed -i "s|dive.lcmlog?mode=w|second.lcmlog?mode=w|" "$dir/config.yaml"
"$laserlined" --config "$dir/config.yaml" --duration 1 >"$dir/daemon2.out" 2>&1 ||
  fail "laserlined: $(cat "$dir/daemon2.out")"
cat "$dir/dive.lcmlog" "$dir/second.lcmlog" >"$dir/two.lcmlog"
"$listen" --url "file://$dir/two.lcmlog" >"$dir/two.out" 2>&1 || fail "listen: $(cat "$dir/two.out")"
grep -q "LASERLINE_PROFILE: messages from two daemons (instance ids [0-9a-f]* and [0-9a-f]*)" \
  "$dir/two.out" || fail "listen did not see two daemons: $(cat "$dir/two.out")"
"$listen" --url "file://$dir/dive.lcmlog" >"$dir/one.out" 2>&1 || fail "listen: $(cat "$dir/one.out")"
! grep -q "two daemons" "$dir/one.out" || fail "listen saw two daemons in one: $(cat "$dir/one.out")"
# A log's latency from its own times (when the daemon wrote each message), not the reading's.
logged=$(sed -n "s/^  latency exposure -> logged (the log's own times): p50 \([0-9.]*\) ms.*/\1/p" \
  "$dir/one.out")
[ -n "$logged" ] && awk -v p50="$logged" 'BEGIN { exit !(p50 >= 0 && p50 < 1000) }' ||
  fail "listen: no latency from the log's times: $(cat "$dir/one.out")"
python3 "$reader" "$dir/two.lcmlog" --types "$types" >"$dir/two.out" 2>&1 || true
grep -q "LASERLINE_STATUS: messages from two daemons" "$dir/two.out" ||
  fail "reader did not see two daemons: $(cat "$dir/two.out")"
echo "test_log_tools: two daemons on one channel reported"
