#!/usr/bin/env bash
# Builds the Debian package (preset "package", prefix /usr) and its -dbgsym package, checks the
# package's files before installing it (stripped programs whose debug information is in the
# -dbgsym package, copyright, sysctl.d, both units through `systemd-analyze verify --root` on the
# unpacked tree), installs it with dpkg, runs laserlined --version, --help and --check-config
# (with --probe as the service's user) from it, checks the installed units with `systemd-analyze
# verify` and `systemd-analyze security --offline`, then purges the package and checks that none of its files is left. Needs root
# (dpkg); registered as the ctest test package_deb. Prints the sizes and the exposure scores.
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
ddeb=$(ls build/package/laserline-dbgsym_*.ddeb)
echo "test-package: built $deb ($(du -k "$deb" | cut -f1) kB, installed" \
  "$(dpkg-deb -f "$deb" Installed-Size) kB) and $ddeb ($(du -k "$ddeb" | cut -f1) kB)"

# ---- The package's files, before it is installed
tree=$(mktemp -d)
trap 'rm -rf "$tree"' EXIT
dpkg-deb -x "$deb" "$tree"
dpkg-deb -x "$ddeb" "$tree"
for program in "$tree"/usr/bin/*; do
  [ "$(head -c 4 "$program")" = $'\x7fELF' ] || continue
  if readelf -S --wide "$program" | grep -q '\.debug_info'; then
    fail "${program#"$tree"} carries debug information"
  fi
  id=$(readelf -n "$program" | sed -n 's/.*Build ID: \([0-9a-f]*\).*/\1/p')
  [ -f "$tree/usr/lib/debug/.build-id/${id:0:2}/${id:2}.debug" ] ||
    fail "no debug information for ${program#"$tree"} (build id $id) in $ddeb"
done
grep -q 'liblcm-bin' <<<"$(dpkg-deb -f "$deb" Recommends)" || fail "liblcm-bin is not recommended"
copyright=$tree/usr/share/doc/laserline/copyright
[ -f "$copyright" ] || fail "no /usr/share/doc/laserline/copyright"
head -1 "$copyright" | grep -q '^Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/' ||
  fail "the copyright file is not in the machine-readable format"
grep -q '^License: Expat' "$copyright" || fail "the copyright file names no licence"
sysctl_file=$tree/usr/lib/sysctl.d/60-laserline.conf
[ -f "$sysctl_file" ] || fail "no /usr/lib/sysctl.d/60-laserline.conf"
grep -q '^net.core.rmem_max' "$sysctl_file" || fail "60-laserline.conf does not set net.core.rmem_max"
while read -r setting; do
  grep -qxF "$setting" docs/hardware.md || fail "60-laserline.conf sets '$setting', which docs/hardware.md does not ask for"
done < <(grep '^net\.' "$sysctl_file")
# systemd-analyze --root resolves every unit and program inside the tree: the host's own units
# stand in for the vehicle's (sysinit.target, ...), the package's programs are its own.
cp -rn /usr/lib/systemd/system/. "$tree/usr/lib/systemd/system/"
for unit in laserlined.service laserlined@port.service; do
  verify=$(systemd-analyze verify --root="$tree" "$unit" 2>&1) ||
    fail "systemd-analyze verify $unit before installation: $verify"
  [ -z "$verify" ] || fail "systemd-analyze verify $unit before installation: $verify"
done
rm -rf "$tree"
trap - EXIT
echo "test-package: before installation: programs stripped, debug information in the -dbgsym" \
  "package, copyright, sysctl.d, systemd-analyze verify of both units: OK"

dpkg -i "$deb" >/dev/null
trap 'dpkg --purge laserline >/dev/null 2>&1 || true' EXIT
mapfile -t files < <(dpkg -L laserline)

expect_file() { [ -f "$1" ] || fail "$1 is not installed"; }
expect_file /usr/bin/laserlined
expect_file /usr/bin/laserline-listen
expect_file /usr/lib/systemd/system/laserlined.service
expect_file /usr/lib/systemd/system/laserlined@.service
expect_file /usr/lib/sysctl.d/60-laserline.conf
expect_file /usr/share/doc/laserline/copyright
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
expect_file /usr/bin/laserline-spy
[ "$(/usr/bin/laserline-spy --classpath | cut -d: -f1)" = /usr/share/java/laserline-lcmtypes.jar ] ||
  fail "laserline-spy does not find the installed types: $(/usr/bin/laserline-spy --classpath 2>&1)"
expect_file /usr/bin/laserline-view
/usr/bin/laserline-view --help | grep -q '^usage: laserline-view' ||
  fail "laserline-view --help printed no usage (its HTTP library missing from Depends?)"
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
runuser -u laserline -- /usr/bin/laserlined --check-config --probe \
  --config /etc/laserline/laserline.yaml >/dev/null ||
  fail "--check-config --probe as the laserline user failed on the installed configuration"
echo "test-package: $version; --help, --check-config and the laserline user OK"

# verify prints nothing for a clean unit; an instance of the template reads /etc/laserline/NAME.yaml.
grep -qx 'ExecStart=/usr/bin/laserlined --config /etc/laserline/%i.yaml' \
  /usr/lib/systemd/system/laserlined@.service || fail "laserlined@.service does not read NAME.yaml"
for unit in laserlined.service laserlined@port.service; do
  verify=$(systemd-analyze verify "$unit" 2>&1) || fail "systemd-analyze verify $unit: $verify"
  [ -z "$verify" ] || fail "systemd-analyze verify $unit: $verify"
  security=$(systemd-analyze security --offline=yes "$unit" 2>&1 || true)
  score=$(sed -n "s/.*Overall exposure level for $unit: \([0-9.]*\) .*/\1/p" <<<"$security")
  [ -n "$score" ] || fail "no exposure score for $unit from systemd-analyze security: $security"
  echo "test-package: $unit: systemd-analyze verify clean, security --offline exposure $score"
  awk -v s="$score" 'BEGIN { exit !(s <= 3.0) }' || fail "$unit: exposure $score is above 3.0"
done

dpkg --purge laserline >/dev/null
trap - EXIT
left=()
for f in "${files[@]}"; do
  # Directories shared with other packages (/usr/bin, ...) stay; files must all be gone.
  if [ -e "$f" ] && [ ! -d "$f" ]; then left+=("$f"); fi
done
[ ${#left[@]} -eq 0 ] || fail "left after purge: ${left[*]}"
[ ! -e /etc/laserline ] || fail "/etc/laserline left after purge"
echo "test-package: purged, no file left; ${SECONDS} s in all"
