#!/usr/bin/env bash
# Builds the Debian package (preset "package", prefix /usr), installs it with dpkg, runs
# laserlined --version, --help and --check-config from it, checks the installed unit with
# `systemd-analyze verify` and `systemd-analyze security --offline`, then purges the package and
# checks that none of its files is left. Needs root (dpkg); registered as the ctest test
# package_deb. Prints the security exposure score.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
if [ "$(id -u)" -ne 0 ]; then
  echo "[  SKIPPED ] package_deb: dpkg -i needs root"
  exit 0
fi
if [ "$(dpkg-query -W -f='${Status}' laserline 2>/dev/null || true)" = "install ok installed" ]; then
  echo "[  SKIPPED ] package_deb: a laserline package is already installed here; left alone"
  exit 0
fi
fail() {
  echo "test-package: FAILED: $*" >&2
  exit 1
}

cd "$root"
cmake --preset package >/dev/null
cmake --build --preset package -j2 >/dev/null
rm -f build/package/laserline_*.deb
(cd build/package && cpack -G DEB >/dev/null)
deb=$(ls build/package/laserline_*.deb)
echo "test-package: built $deb"

dpkg -i "$deb" >/dev/null
trap 'dpkg --purge laserline >/dev/null 2>&1 || true' EXIT
mapfile -t files < <(dpkg -L laserline)

expect_file() { [ -f "$1" ] || fail "$1 is not installed"; }
expect_file /usr/bin/laserlined
expect_file /usr/bin/laserline-listen
expect_file /usr/lib/systemd/system/laserlined.service
expect_file /usr/lib/sysusers.d/laserline.conf
expect_file /usr/lib/udev/rules.d/60-laserline.rules
expect_file /etc/laserline/laserline.yaml
expect_file /usr/share/laserline/lcmtypes/laserline_profile_t.lcm
expect_file /usr/include/laserline/profile_t.hpp
expect_file /usr/include/laserline_profile_t.h
expect_file /usr/lib/x86_64-linux-gnu/liblaserline-lcmtypes.a
expect_file /usr/lib/python3/dist-packages/laserline/profile_t.py
expect_file /usr/share/java/laserline-lcmtypes.jar
expect_file /usr/bin/laserline-log-reader
expect_file /usr/bin/laserline-example-subscriber
/usr/bin/python3 -c 'import laserline; laserline.profile_t.decode(laserline.profile_t().encode())' ||
  fail "the installed Python types do not work with the system python3"
grep -qx /etc/laserline/laserline.yaml /var/lib/dpkg/info/laserline.conffiles ||
  fail "/etc/laserline/laserline.yaml is not a conffile"

version=$(/usr/bin/laserlined --version)
[ "$version" = "laserlined $(sed -n 's/^project(laserline VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)" ] ||
  fail "--version printed '$version'"
/usr/bin/laserlined --help | grep -q '^usage: laserlined' || fail "--help printed no usage"
/usr/bin/laserlined --check-config --config /etc/laserline/laserline.yaml >/dev/null ||
  fail "the installed configuration does not validate"
getent passwd laserline >/dev/null || fail "postinst did not create the laserline user"
echo "test-package: $version; --help, --check-config and the laserline user OK"

# verify prints nothing for a clean unit.
verify=$(systemd-analyze verify /usr/lib/systemd/system/laserlined.service 2>&1) ||
  fail "systemd-analyze verify: $verify"
[ -z "$verify" ] || fail "systemd-analyze verify: $verify"
echo "test-package: systemd-analyze verify: clean"
security=$(systemd-analyze security --offline=yes /usr/lib/systemd/system/laserlined.service 2>&1 || true)
score=$(sed -n 's/.*Overall exposure level for laserlined.service: \([0-9.]*\) .*/\1/p' <<<"$security")
[ -n "$score" ] || fail "no exposure score from systemd-analyze security: $security"
echo "test-package: systemd-analyze security --offline: exposure $score"
awk -v s="$score" 'BEGIN { exit !(s <= 3.0) }' || fail "exposure $score is above 3.0"

dpkg --purge laserline >/dev/null
trap - EXIT
left=()
for f in "${files[@]}"; do
  # Directories shared with other packages (/usr/bin, ...) stay; files must all be gone.
  if [ -e "$f" ] && [ ! -d "$f" ]; then left+=("$f"); fi
done
[ ${#left[@]} -eq 0 ] || fail "left after purge: ${left[*]}"
[ ! -e /etc/laserline ] || fail "/etc/laserline left after purge"
echo "test-package: purged, no file left"
