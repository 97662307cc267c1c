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
)

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: not root and sudo is missing" >&2; exit 1; }
  sudo_cmd=(sudo)
fi

missing=()
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [ "$status" = "install ok installed" ] || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages already installed"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
