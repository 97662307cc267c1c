#!/usr/bin/env bash
# Builds the libFuzzer harnesses (tests/fuzz/) with clang under ASan and UBSan in their own build
# directory and runs each for SECONDS (default 20). Fails on the first crash, leak, exception or
# undefined behaviour, leaving the input in build/fuzz/crashes/.
#   scripts/fuzz.sh [SECONDS] [HARNESS...]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-20}
shift || true
harnesses=("$@")
[ ${#harnesses[@]} -gt 0 ] || harnesses=(profile status point calibration_message image_message image_payload lcm_log
                                          config calibration poses command)
build=build/fuzz
CC=clang-16 CXX=clang++-16 cmake -S tests/fuzz -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$build" -j2 --target make_fuzz_seeds "${harnesses[@]/#/fuzz_}"

seeds=$build/seeds
rm -rf "$seeds"
"$build/make_fuzz_seeds" "$seeds"
mkdir -p "$seeds/config" "$seeds/calibration" "$seeds/poses"
# A navigation log as laserline-extract --poses reads it: a header, a turn about z, a gap.
printf 'timestamp,x,y,z,qw,qx,qy,qz\n0.0,0,0,0,1,0,0,0\n0.5,0.1,0,-2,0.9238795,0,0,0.3826834\n2.0,0.4,0.05,-2.1,0.7071068,0,0,0.7071068\n' \
  >"$seeds/poses/turn.csv"
cp config/laserline.yaml "$seeds/config/"
# The calibration section of the configuration, as a calibration file of its own.
sed -n '/^calibration:/,/^[a-z]/p' config/laserline.yaml | sed '1d;$d;s/^  //' \
  >"$seeds/calibration/section.yaml"

mkdir -p "$build/crashes"
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=0
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
total=0
for h in "${harnesses[@]}"; do
  corpus=$build/corpus/$h
  mkdir -p "$corpus"
  # -rss_limit_mb and -malloc_limit_mb: a decoder that allocates beyond its limits is a failure.
  log=$build/$h.log
  # timeout: a harness stopped by its own memory limit has been seen to hang while reporting it.
  if ! timeout --signal=KILL $((seconds * 2 + 120)) "$build/fuzz_$h" "$corpus" "$seeds/$h" -max_total_time="$seconds" -rss_limit_mb=1024 \
      -malloc_limit_mb=512 -max_len=65536 -timeout=10 -print_final_stats=1 \
      -artifact_prefix="$build/crashes/$h-" >"$log" 2>&1; then
    tail -n 40 "$log" >&2
    echo "fuzz: $h FAILED (input in $build/crashes/, log $log)" >&2
    exit 1
  fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
  total=$((total + ${runs:-0}))
  echo "fuzz: $h: ${runs:-0} executions in ${seconds}s, no failure"
done
echo "fuzz: ${#harnesses[@]} harnesses, $total executions"
