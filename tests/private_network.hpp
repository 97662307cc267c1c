#pragma once

#include <sched.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

namespace laserline::test {

// Moves this process into a private network namespace with multicast on loopback, so that LCM
// over UDP multicast stays on this machine. Root: a network namespace. Otherwise: a user
// namespace too, in which we are root. Call before any thread exists. Returns "" on success,
// else why it could not be done (the caller skips its tests with that reason).
inline std::string enter_private_network() {
  auto write_file = [](const char* path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    return static_cast<bool>(out.flush());
  };
  const uid_t uid = geteuid();
  const gid_t gid = getegid();
  if (uid == 0) {
    if (unshare(CLONE_NEWNET) != 0) return std::string("unshare(CLONE_NEWNET): ") + strerror(errno);
  } else {
    if (unshare(CLONE_NEWUSER | CLONE_NEWNET) != 0) {
      return std::string("not root and unshare(CLONE_NEWUSER|CLONE_NEWNET) failed: ") +
             strerror(errno);
    }
    write_file("/proc/self/setgroups", "deny");
    if (!write_file("/proc/self/uid_map", "0 " + std::to_string(uid) + " 1\n") ||
        !write_file("/proc/self/gid_map", "0 " + std::to_string(gid) + " 1\n")) {
      return "cannot map ids in the user namespace";
    }
  }
  if (std::system("ip link set lo up multicast on") != 0) return "'ip link set lo up' failed";
  if (std::system("ip route add 224.0.0.0/4 dev lo") != 0) return "'ip route add' failed";
  return "";
}

}  // namespace laserline::test
