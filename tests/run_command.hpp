#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

namespace laserline::test_support {

// What a shell command printed (stdout and stderr together) and its exit status (-1 when it did
// not exit normally or could not be started).
struct CommandResult {
  int exit_code = -1;
  std::string out;
};

inline CommandResult run_command(const std::string& command) {
  CommandResult r;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return r;
  std::array<char, 4096> buffer{};
  while (std::fgets(buffer.data(), buffer.size(), pipe) != nullptr)
    r.out += buffer.data();
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace laserline::test_support
