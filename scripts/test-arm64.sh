#!/usr/bin/env bash
# The arm64 stage of the test suite: cross-builds the pipeline and the tests that need only it
# (preset "arm64", Debian's g++-aarch64-linux-gnu, build/arm64) and runs them under qemu-user;
# then every detector over the same simulated frames on x86-64 and under qemu on two arm64 CPUs,
# one with SVE/SVE2 (qemu's "max") and one with NEON only (Cortex-A76), and the profiles must be
# identical to the bit. Needs scripts/install-deps.sh's packages.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
scripts/build.sh arm64
ctest --preset arm64 --timeout 300
# The frames and the x86-64 profiles from the native build.
scripts/build.sh default make_parity_frames profile_parity
out=build/arm64/parity
mkdir -p "$out"
build/default/tests/make_parity_frames "$out/frames.bin"
build/default/tests/profile_parity detect "$out/frames.bin" "$out/x86-64.txt"
for cpu in max cortex-a76; do
  qemu-aarch64 -cpu "$cpu" -L /usr/aarch64-linux-gnu build/arm64/tests/profile_parity detect \
    "$out/frames.bin" "$out/arm64-$cpu.txt"
  build/default/tests/profile_parity compare "$out/x86-64.txt" "$out/arm64-$cpu.txt"
done
echo "test-arm64.sh: took $(($(date +%s) - start)) s"
