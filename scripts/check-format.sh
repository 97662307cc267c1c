#!/usr/bin/env bash
# Fails (and lists the files) when any C++ source differs from what .clang-format makes of it.
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' 2>/dev/null || find daemon hal pipeline tools tests bench -name '*.[ch]pp')
bad=()
for f in "${files[@]}"; do
  [ -f "$f" ] || continue
  clang-format --dry-run --Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done
if [ ${#bad[@]} -gt 0 ]; then
  echo "not formatted with clang-format: ${bad[*]}"
  exit 1
fi
echo "clang-format: ${#files[@]} files formatted"
