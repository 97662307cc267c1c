#!/usr/bin/env bash
# Installs the Debian packages, builds, and runs the whole test suite with ctest.
# Works as root or as a user with sudo; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh default
# One test at a time: the end-to-end tests pace a camera in real time and judge frame timing.
ctest --preset default --timeout 300
