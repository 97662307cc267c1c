#!/usr/bin/env bash
# Installs the Debian 12 packages laserline builds, tests and runs with. Idempotent and
# non-interactive; uses sudo when not run as root. Only Debian packages, nothing downloaded
# from anywhere else.
set -euo pipefail

packages=(
  # build
  build-essential cmake pkg-config git clang-format ccache
  # libraries
  liblcm-dev liblcm-bin liblcm-java libglib2.0-dev
  # the Java message types (a jar for lcm-spy) and the Python log reader
  default-jdk-headless python3
  # scripts/plot-scaling.py (docs/figures/scaling.png)
  python3-matplotlib
  # laserline-spy: lcm-spy's window and charts; Xvfb for its test
  default-jre libjchart2d-java fonts-dejavu-core xvfb xauth
  libyaml-cpp-dev
  libopencv-dev
  libeigen3-dev
  # the pipeline's vector kernels, one source for every CPU (SSE4/AVX2/AVX-512, NEON/SVE)
  libhwy-dev
  libsystemd-dev
  zlib1g-dev
  # laserline-view's HTTP server
  libcpp-httplib-dev
  # hardware backends: GPIO laser (libgpiod 1.6), GigE Vision cameras (Aravis; its pkg-config
  # file needs libusb's), V4L2 stand-in device (FUSE)
  libgpiod-dev gpiod
  libaravis-dev libusb-1.0-0-dev aravis-tools
  libfuse3-dev fuse3
  # tests and benchmarks; the fuzz harnesses (clang 16 with libFuzzer and the sanitizers)
  libgtest-dev libgmock-dev libbenchmark-dev clang-16 libclang-rt-16-dev
  # laserline-view's test in a real browser (headless, driven over its DevTools protocol)
  chromium
  # network namespaces for the LCM tests and the demo
  iproute2 util-linux
  # the service: systemd-analyze verify/security and systemd-sysusers in the tests, the .deb
  # (file: how CPack tells the programs it strips and scans for their libraries)
  systemd dpkg-dev file
  # the arm64 cross build of the pipeline and its tests (scripts/test-arm64.sh): Debian's cross
  # compiler, qemu-user to run what it builds, and the arm64 libraries it links (multiarch)
  g++-aarch64-linux-gnu qemu-user libgtest-dev:arm64 libgmock-dev:arm64 libhwy-dev:arm64
)

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: not root and sudo is missing" >&2; exit 1; }
  sudo_cmd=(sudo)
fi

# The arm64 packages need the architecture known to dpkg (once; apt then fetches its lists).
if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  echo "install-deps: adding the arm64 architecture (for the cross build's libraries)"
  "${sudo_cmd[@]}" dpkg --add-architecture arm64
fi

# Installed: of the host's architecture (or for all), unless the name says which (NAME:arm64).
native=$(dpkg --print-architecture)
installed() {
  local name=${1%%:*} arch=${1#*:}
  [ "$arch" != "$1" ] || arch=$native
  dpkg-query -W -f='${Architecture} ${Status}\n' "$name" 2>/dev/null |
    grep -qE "^($arch|all) install ok installed\$"
}
missing=()
for p in "${packages[@]}"; do
  installed "$p" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages already installed"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
