// The systemd notify protocol of the real laserlined, against a listener on $NOTIFY_SOCKET made
// here (systemd is not PID 1 on the development machines): READY, STATUS, WATCHDOG and STOPPING
// arrive in order, and WATCHDOG stops while the simulated camera stalls, then resumes.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "hal/clock.hpp"

namespace {

struct Notification {
  double t_s;  // since the daemon was started
  std::string text;
  bool has(const std::string& key) const { return text.find(key) != std::string::npos; }
};

class NotifySocket {
 public:
  explicit NotifySocket(const std::string& path) : path_(path) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    bound_ = fd_ >= 0 && bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
  }
  ~NotifySocket() {
    if (fd_ >= 0) close(fd_);
    unlink(path_.c_str());
  }
  bool bound() const { return bound_; }
  // Appends what arrives within `timeout_ms`.
  void receive(std::vector<Notification>& out, int timeout_ms, std::int64_t t0) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return;
    char buffer[4096];
    const ssize_t n = recv(fd_, buffer, sizeof buffer, 0);
    if (n <= 0) return;
    out.push_back({static_cast<double>(laserline::hal::monotonic_ns() - t0) * 1e-9,
                   std::string(buffer, static_cast<std::size_t>(n))});
  }

 private:
  std::string path_;
  int fd_ = -1;
  bool bound_ = false;
};

constexpr const char* kConfig = R"(camera:
  backend: sim
  frame_rate_hz: 30
  timeout_ms: 500
  sim: {seed: 5, distance_m: 1.0, stall_after_s: 2.5, stall_for_s: 3.0}
calibration:
  camera: {width: 320, height: 256, fx: 350, fy: 350, cx: 159.5, cy: 127.5}
  laser: {baseline_m: 0.2, angle_deg: 80, sheet_width_m: 0.003}
lcm: {url: "memq://", image_every_n: 0}
)";

TEST(ServiceNotify, ReadyStatusWatchdogStoppingInOrderAndNoWatchdogWhileStalled) {
  const auto dir =
      std::filesystem::temp_directory_path() / ("laserline_notify_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string config = (dir / "notify.yaml").string();
  std::ofstream(config) << kConfig;
  const std::string socket_path = (dir / "notify.sock").string();
  NotifySocket listener(socket_path);
  ASSERT_TRUE(listener.bound()) << socket_path;

  const std::string log = (dir / "daemon.log").string();
  const pid_t parent = getpid();
  const std::int64_t t0 = laserline::hal::monotonic_ns();
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    dup2(fd, 2);
    // What systemd sets for a Type=notify unit with WatchdogSec=1.
    setenv("NOTIFY_SOCKET", socket_path.c_str(), 1);
    setenv("WATCHDOG_USEC", "1000000", 1);
    setenv("WATCHDOG_PID", std::to_string(getpid()).c_str(), 1);
    execl(LASERLINED_PATH, LASERLINED_PATH, "--config", config.c_str(), nullptr);
    _exit(127);
  }
  std::vector<Notification> got;
  // Frames for 2.5 s, a 3 s stall, frames again: 8 s covers it even when slow to start.
  while (laserline::hal::monotonic_ns() - t0 < 8'000'000'000)
    listener.receive(got, 50, t0);
  kill(pid, SIGTERM);
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0)
    listener.receive(got, 20, t0);
  listener.receive(got, 100, t0);
  const std::string daemon_log = [&] {
    std::ifstream in(log);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }();
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << daemon_log;

  std::string trace;
  for (const auto& n : got)
    trace += std::to_string(n.t_s) + " " + n.text + "\n";

  // Order: READY before any WATCHDOG, STATUS in between, STOPPING last.
  std::size_t ready = got.size(), first_watchdog = got.size(), stopping = got.size();
  for (std::size_t i = 0; i < got.size(); ++i) {
    if (got[i].has("READY=1") && ready == got.size()) ready = i;
    if (got[i].has("WATCHDOG=1") && first_watchdog == got.size()) first_watchdog = i;
    if (got[i].has("STOPPING=1")) stopping = i;
  }
  ASSERT_LT(ready, got.size()) << trace;
  ASSERT_LT(first_watchdog, got.size()) << trace;
  ASSERT_LT(stopping, got.size()) << trace;
  EXPECT_LT(ready, first_watchdog) << trace;
  EXPECT_EQ(stopping, got.size() - 1) << "STOPPING is the last word\n" << trace;
  EXPECT_TRUE(got[ready].has("STATUS=")) << "READY comes with a status line";
  int statuses_between = 0;
  for (std::size_t i = ready + 1; i < stopping; ++i)
    statuses_between += got[i].has("STATUS=") ? 1 : 0;
  EXPECT_GE(statuses_between, 3) << trace;

  // The watchdog: fed while frames flow, silent during the stall while STATUS goes on saying
  // why, fed again when frames return.
  std::vector<std::size_t> pings;
  for (std::size_t i = 0; i < got.size(); ++i) {
    if (got[i].has("WATCHDOG=1")) pings.push_back(i);
  }
  std::size_t gap_begin = 0;
  double widest = 0;
  for (std::size_t k = 1; k < pings.size(); ++k) {
    const double gap = got[pings[k]].t_s - got[pings[k - 1]].t_s;
    if (gap > widest) {
      widest = gap;
      gap_begin = k - 1;
    }
  }
  ASSERT_GE(pings.size(), 3u) << trace;
  EXPECT_GE(widest, 2.0) << "a 3 s stall must silence the watchdog\n" << trace;
  bool stalled_status = false;
  for (std::size_t i = pings[gap_begin] + 1; i < pings[gap_begin + 1]; ++i) {
    stalled_status |= got[i].has("STATUS=camera timeout") && got[i].has("laser off");
  }
  EXPECT_TRUE(stalled_status) << "the daemon lives on and says the camera stalled\n" << trace;
  EXPECT_GE(gap_begin, 1u) << "pings before the stall\n" << trace;
  // pings[gap_begin + 1] is the watchdog fed again once frames returned.
  for (std::size_t k : pings)
    EXPECT_LT(k, stopping) << "no WATCHDOG after STOPPING";
}

}  // namespace
