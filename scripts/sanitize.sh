#!/usr/bin/env bash
# The sanitizer stage of the test suite: the tests labelled "input" (code that reads files,
# messages and flags from outside) built and run under AddressSanitizer + UndefinedBehavior-
# Sanitizer, those labelled "concurrent" (code on several threads) under ThreadSanitizer.
# The labels are set in tests/CMakeLists.txt. Usage: scripts/sanitize.sh [asan|tsan]...
set -euo pipefail
cd "$(dirname "$0")/.."
stages=("$@")
[ ${#stages[@]} -gt 0 ] || stages=(asan tsan)
for stage in "${stages[@]}"; do
  case $stage in
    asan) label=input ;;
    tsan) label=concurrent ;;
    *) echo "sanitize.sh: unknown stage '$stage' (asan or tsan)" >&2; exit 2 ;;
  esac
  start=$(date +%s)
  scripts/build.sh "$stage" "tests_$label"
  ctest --preset "$stage" -L "^$label\$" --timeout 300 --repeat until-pass:2
  echo "sanitize.sh: $stage ($label) took $(( $(date +%s) - start )) s"
done
