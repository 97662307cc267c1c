// laserlined's command line and start-up validation, run as the real executable.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include "run_command.hpp"

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

namespace {

using CliResult = laserline::test_support::CommandResult;

// Runs laserlined with `args`, behind `prefix` (a command that wraps it, or "").
CliResult run_prefixed(const std::string& prefix, const std::string& args) {
  return laserline::test_support::run_command(prefix + " " + std::string(LASERLINED_PATH) + " " +
                                              args);
}

CliResult run(const std::string& args) {
  return run_prefixed("", args);
}

std::size_t lines(const std::string& text) {
  std::size_t n = 0;
  for (char c : text)
    n += c == '\n';
  return n;
}

class LaserlinedCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("laserline_cli_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string file(const std::string& name, const std::string& text) {
    const auto path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  std::filesystem::path dir_;
};

TEST_F(LaserlinedCli, BadConfigFailsWithOneLineNamingFileLineAndKey) {
  const std::string path = file("bad.yaml", "camera:\n  backend: sim\n  frame_rte_hz: 30\n");
  const CliResult r = run("--config " + path);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.out), 1u) << r.out;
  EXPECT_EQ(r.out, "laserlined: " + path +
                       ":3: camera.frame_rte_hz: unknown key (expected one of: backend, "
                       "channel, frame_rate_hz, sim, timeout_ms)\n");
}

TEST_F(LaserlinedCli, OutOfRangeAndWrongTypeFailBeforeAnythingStarts) {
  for (const char* text :
       {"camera: {frame_rate_hz: -5}\n", "laser: {mode: 3}\n",
        "calibration: {camera: {width: many}}\n", "lcm: {url: ''}\n", "camera: {sim: {seed: -1}}\n",
        "camera: {channel: 'red * green'}\n",
        "camera: {backend: v4l2, device: /dev/video9, pixel_format: YUYV}\n"
        "calibration: {camera: {width: 641, height: 480}}\n",
        // A depth range no row of the image sees: the detector cannot work.
        "detector: {name: fir, frontend: {min_depth_m: 0.1, max_depth_m: 0.2}}\n",
        "detector: {name: background, motion: {detect_level: 5}}\n"}) {
    const CliResult r = run("--config " + file("bad.yaml", text));
    EXPECT_EQ(r.exit_code, 2) << text << r.out;
    EXPECT_EQ(lines(r.out), 1u) << text << r.out;
    EXPECT_EQ(r.out.find("running"), std::string::npos) << "must not start: " << r.out;
  }
}

TEST_F(LaserlinedCli, MissingConfigFile) {
  const CliResult r = run("--config /nonexistent/x.yaml");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out,
            "laserlined: /nonexistent/x.yaml: cannot be opened for reading: No such file or "
            "directory\n");
}

TEST_F(LaserlinedCli, BadFlags) {
  CliResult r = run("--frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserlined: unknown option '--frobnicate' (see --help)\n");
  r = run("--duration soon");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out,
            "laserlined: --duration: expected a number of seconds from 0.001 to 1e9, got "
            "'soon'\n");
  r = run("--config");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserlined: --config: missing value (see --help)\n");
}

TEST_F(LaserlinedCli, CheckConfigValidatesWithoutRunning) {
  const CliResult r =
      run("--check-config --config " + file("good.yaml", "laser: {mode: alternate}\n"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("configuration is valid"), std::string::npos);
  const CliResult builtin = run("--check-config");
  EXPECT_EQ(builtin.exit_code, 0) << builtin.out;

  // A calibration whose laser sheet lies behind the camera is refused, naming its file.
  const std::string calib = file("calib.yaml",
                                 "camera: {width: 1280, height: 1024, fx: 1400, fy: 1400}\n"
                                 "laser: {plane: [0, 0.5, 0.866, 0.25]}\n");
  const CliResult behind =
      run("--check-config --config " + file("behind.yaml", "calibration: " + calib + "\n"));
  EXPECT_EQ(behind.exit_code, 2) << behind.out;
  EXPECT_EQ(lines(behind.out), 1u) << behind.out;
  EXPECT_EQ(behind.out.rfind("laserlined: " + calib +
                                 ": laser.plane: the sheet [0, 0.5, 0.866, 0.25] lies behind the "
                                 "camera at every pixel",
                             0),
            0u)
      << behind.out;
}

TEST_F(LaserlinedCli, PrintedDefaultConfigIsTheShippedFileAndValid) {
  const CliResult printed = run("--print-default-config");
  EXPECT_EQ(printed.exit_code, 0);
  std::ifstream shipped(LASERLINE_SOURCE_DIR "/config/laserline.yaml");
  const std::string expected(std::istreambuf_iterator<char>(shipped), {});
  EXPECT_EQ(printed.out, expected);
  const CliResult check = run("--check-config --config " + file("default.yaml", printed.out));
  EXPECT_EQ(check.exit_code, 0) << check.out;
}

TEST_F(LaserlinedCli, BadLcmUrlFailsBeforeAnythingStarts) {
  CliResult r = run("--duration 1 --config " + file("lcm.yaml", "lcm: {url: 'nonsense://x'}\n"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.out), 1u) << r.out;
  EXPECT_NE(r.out.find(":1: lcm.url: must be udpm://, memq://, file:// or tcpq://, got "
                       "'nonsense://x'"),
            std::string::npos)
      << r.out;
  // A known provider with a bad address: LCM says why on its own line, then ours names the key.
  r = run("--duration 1 --config " + file("lcm.yaml", "lcm: {url: 'udpm://999.1.1.1:7667'}\n"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.out), 1u) << "LCM's own complaint belongs in the one line: " << r.out;
  EXPECT_NE(r.out.find("lcm.url: cannot open 'udpm://999.1.1.1:7667': "), std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("running"), std::string::npos) << r.out;
}

// LCM creates a tcpq:// instance even when no hub answers, and then tries to connect again, in
// three lines of its own, for every message it is given: refused at start instead.
TEST_F(LaserlinedCli, TcpqWithoutHubFailsWithOneLine) {
  const CliResult r =
      run("--duration 2 --config " + file("tcpq.yaml", "lcm: {url: 'tcpq://127.0.0.1:1'}\n"));
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_EQ(lines(r.out), 1u) << r.out;
  EXPECT_NE(r.out.find("lcm.url: cannot open 'tcpq://127.0.0.1:1': no tcpq hub answered: "),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("Connection refused"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("running"), std::string::npos) << r.out;
}

// Whether something accepts TCP connections on 127.0.0.1:`port`.
bool listening(int port) {
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const bool ok = connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
  close(fd);
  return ok;
}

// The refusal above is for a hub that is not there: with LCM's own hub (Java's TCPService,
// on loopback) the daemon runs and publishes through it.
TEST_F(LaserlinedCli, TcpqWithHubRuns) {
  if (std::string(LASERLINE_LCM_JAR).empty() || std::system("java -version >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "no Java or no lcm.jar: no tcpq hub to run";
  }
  const int port = 20000 + getpid() % 20000;
  const auto pid_file = dir_ / "hub.pid";
  ASSERT_EQ(std::system(("java -cp " LASERLINE_LCM_JAR " lcm.lcm.TCPService " +
                         std::to_string(port) + " >/dev/null 2>&1 & echo $! > " + pid_file.string())
                            .c_str()),
            0);
  for (int i = 0; i < 300 && !listening(port); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const bool hub_up = listening(port);
  CliResult r;
  if (hub_up) {
    r = run("--duration 0.5 --config " +
            file("tcpq.yaml",
                 "calibration: {camera: {width: 320, height: 240, fx: 350, fy: "
                 "350}}\ndetector: {name: maxvalue}\nlcm: {url: 'tcpq://127.0.0.1:" +
                     std::to_string(port) + "'}\n"));
  }
  std::ifstream pid_in(pid_file);
  pid_t hub = 0;
  if (pid_in >> hub && hub > 0) kill(hub, SIGTERM);
  ASSERT_TRUE(hub_up) << "LCM's tcpq hub did not listen on port " << port;
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("running"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(" 0 profiles published"), std::string::npos) << r.out;
}

// Durations that are no number, not positive, or too small or too large to count in nanoseconds
// (1e-300 was taken as "until signalled", 1e300 overflowed) are refused in one line naming the
// flag; the smallest allowed ends at the first look at the clock.
TEST_F(LaserlinedCli, DurationOutOfRangeIsOneLineNamingTheFlag) {
  for (const char* value :
       {"1e-300", "1e300", "nan", "inf", "-inf", "-1", "0", "0.0009", "1e10", "5s", "''"}) {
    const CliResult r = run(std::string("--duration ") + value);
    EXPECT_EQ(r.exit_code, 2) << value << ": " << r.out;
    EXPECT_EQ(lines(r.out), 1u) << value << ": " << r.out;
    EXPECT_EQ(r.out.rfind("laserlined: --duration: expected a number of seconds from 0.001 to 1e9, "
                          "got '",
                          0),
              0u)
        << r.out;
  }
  const std::string config = file("short.yaml",
                                  "calibration: {camera: {width: 320, height: 240, fx: 350, "
                                  "fy: 350}}\ndetector: {name: maxvalue}\nlcm: {url: 'memq://'}\n");
  const CliResult r = run("--duration 0.001 --config " + config);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("laserlined: stopped (duration elapsed) after 0."), std::string::npos)
      << r.out;
}

// Real-time scheduling is granted or refused by the system; refused must be one clear line and
// a non-zero exit before the camera starts. setpriv (util-linux) takes every capability away, so
// this runs the refusal even as root.
TEST_F(LaserlinedCli, RealtimeRefusedIsOneClearLine) {
  if (std::system("setpriv --help >/dev/null 2>&1") != 0) GTEST_SKIP() << "no setpriv";
  const std::string config = file("rt.yaml", "realtime: {enabled: true}\nlcm: {url: 'memq://'}\n");
  const std::string no_caps = "--duration 1 --config " + config;
  // Memory locking refused: no CAP_IPC_LOCK and RLIMIT_MEMLOCK lowered to 64 KiB.
  CliResult r = run_prefixed(
      "prlimit --memlock=65536:65536 setpriv --inh-caps=-all --bounding-set=-all --", no_caps);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_EQ(lines(r.out), 1u) << r.out;
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // The sanitizers turn mlockall into a no-op (their shadow memory must not be locked), so the
  // next check refuses instead: SCHED_FIFO, as no capability is left either.
  EXPECT_NE(r.out.find("realtime.enabled: SCHED_FIFO priority 60 refused"), std::string::npos)
      << r.out;
#else
  EXPECT_NE(r.out.find("realtime.enabled: cannot lock memory"), std::string::npos) << r.out;
#endif
  // Memory may be locked (root keeps CAP_IPC_LOCK) but SCHED_FIFO is refused: no CAP_SYS_NICE
  // and RLIMIT_RTPRIO 0.
  if (geteuid() != 0) GTEST_SKIP() << "the SCHED_FIFO refusal case needs root's CAP_IPC_LOCK";
  r = run_prefixed("prlimit --rtprio=0 setpriv --bounding-set=-sys_nice --", no_caps);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_EQ(lines(r.out), 1u) << r.out;
  EXPECT_NE(r.out.find("realtime.enabled: SCHED_FIFO priority 60 refused"), std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("running"), std::string::npos) << "must stop before the camera starts";
}

TEST_F(LaserlinedCli, RealtimeGrantedRuns) {
  if (geteuid() != 0) GTEST_SKIP() << "only root is sure to be granted SCHED_FIFO here";
  // Small frames and the cheapest detector: every real-time thread shares CPU 0 here, and a
  // sanitized build must still keep up.
  const CliResult r =
      run("--duration 0.5 --config " +
          file("rt.yaml",
               "realtime: {enabled: true, cpus: [0]}\n"
               "calibration: {camera: {width: 320, height: 240, fx: 350, fy: 350}}\n"
               "detector: {name: maxvalue}\n"
               "lcm: {url: 'memq://'}\n"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("running"), std::string::npos) << r.out;
}

}  // namespace

// --check-config on what an outside tester gave laserlined (issue 15): each case is refused by
// the check with one line, as the start would refuse it (or crash, before); a configuration the
// check passes starts and runs on the simulator.
namespace {

class CheckConfigHostile : public LaserlinedCli {
 protected:
  // Refused by --check-config with exit status 2 and exactly `line` (the directory left out).
  void expect_refused(const std::string& config_path, const std::string& line) {
    const CliResult r = run("--check-config --config " + config_path);
    EXPECT_EQ(r.exit_code, 2) << r.out;
    EXPECT_EQ(lines(r.out), 1u) << r.out;
    std::string out = r.out;
    for (std::size_t at; (at = out.find(dir_.string() + "/")) != std::string::npos;)
      out.erase(at, dir_.string().size() + 1);
    EXPECT_EQ(out, "laserlined: " + line + "\n");
  }
};

TEST_F(CheckConfigHostile, DerivedSizesAreCheckedAsTheStartDoes) {
  expect_refused(file("roi_x.yaml", "lcm: {image_roi: [2147483647, 0, 16, 16]}\n"),
                 "roi_x.yaml:1: lcm.image_roi: [2147483647, 0, 16, 16] is not inside the "
                 "calibration's 1280x1024 frame");
  expect_refused(file("roi_w.yaml", "lcm: {image_roi: [1, 0, 2147483647, 16]}\n"),
                 "roi_w.yaml:1: lcm.image_roi: [1, 0, 2147483647, 16] is not inside the "
                 "calibration's 1280x1024 frame");
  expect_refused(file("small.yaml",
                      "calibration: {camera: {width: 16, height: 16, fx: 20, fy: "
                      "20}}\n"),
                 "small.yaml: detector background: frames of 16x16 (calibration.camera): frame "
                 "smaller than 64x4 pixels");
  expect_refused(file("huge.yaml",
                      "calibration: {camera: {width: 16384, height: 16384, fx: "
                      "20000, fy: 20000}}\npipeline: {frame_slots: 1024}\n"),
                 "huge.yaml: pipeline.frame_memory_limit_mb: frames of 16384x16384 need 276860.8 "
                 "MB (pipeline.frame_slots 1024, image_slots 2, profile_slots 16 and the "
                 "raw-frame buffers), more than the limit of 1024 MB: fewer slots, a smaller "
                 "camera or a higher limit");
}

TEST_F(CheckConfigHostile, OnlyOneRegularFileOfYamlIsAConfiguration) {
  expect_refused(dir_.string(), dir_.string() +
                                    ": is a directory, not a file: give a configuration or "
                                    "calibration file");
  expect_refused("/dev/null",
                 "/dev/null: is a character device, not a file: give a configuration or "
                 "calibration file");
  expect_refused(file("empty.yaml", ""), "empty.yaml: has no keys (empty, or only comments)");
  const std::string fifo = (dir_ / "fifo.yaml").string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  expect_refused(fifo,
                 "fifo.yaml: is a named pipe (FIFO), not a file: give a configuration or "
                 "calibration file");
  expect_refused(file("deep.yaml", "a: " + std::string(10000, '[') + std::string(10000, ']')),
                 "deep.yaml:1: nested more than 32 levels deep");
  expect_refused(file("two.yaml", "laser: {mode: on}\n---\nlaser: {mode: off}\n"),
                 "two.yaml:3: a second YAML document (after '---'): only one is read, give all "
                 "keys in one");
  expect_refused(file("nul.yaml", "lcm: {status_channel: \"STATUS\\0HIDDEN\"}\n"),
                 "nul.yaml:1: lcm.status_channel: contains a NUL byte: \"STATUS\\0HIDDEN\"");
  expect_refused(
      file("calib_dir.yaml", "calibration: " + dir_.string() + "\n"),
      dir_.string() + ": is a directory, not a file: give a configuration or calibration file");
}

// What the check passes starts: the last pixels of the frame as the region, the frame-path's
// memory near its limit, the smallest frame the maxvalue detector takes.
TEST_F(CheckConfigHostile, WhatTheCheckPassesStarts) {
  for (const std::string text :
       {"lcm: {url: 'memq://', image_every_n: 1, image_roi: [1272, 1020, 8, 4], image_downscale: "
        "4}\n",
        "lcm: {url: 'memq://'}\npipeline: {frame_slots: 64, frame_memory_limit_mb: 128}\n",
        "lcm: {url: 'memq://'}\ndetector: {name: maxvalue}\n"
        "calibration: {camera: {width: 64, height: 16, fx: 80, fy: 80}}\n"}) {
    const std::string path = file("good.yaml", text);
    const CliResult check = run("--check-config --config " + path);
    EXPECT_EQ(check.exit_code, 0) << text << check.out;
    const CliResult started = run("--duration 0.5 --config " + path);
    EXPECT_EQ(started.exit_code, 0) << text << started.out;
    EXPECT_NE(started.out.find("running"), std::string::npos) << started.out;
    EXPECT_NE(started.out.find("stopped (duration elapsed)"), std::string::npos) << started.out;
  }
}

}  // namespace

// Journal priorities: under systemd, stdout and stderr are the journal's stream and
// JOURNAL_STREAM names its device and inode; each line then starts with its syslog level, so
// that `journalctl -p err` finds the errors. Here a file stands in for the stream.
namespace {

class JournalPriorities : public LaserlinedCli {
 protected:
  // Runs laserlined with stdout and stderr on the file `name`; JOURNAL_STREAM names
  // `stream_file`'s device and inode when given. Returns what the file holds.
  CliResult run_to_file(const std::string& args, const std::string& stream_file = "",
                        const std::string& shell_after = "") {
    const std::string out = (dir_ / "out.txt").string();
    std::ofstream(out).close();
    std::string env;
    if (!stream_file.empty()) {
      struct stat st {};
      if (stat(stream_file.c_str(), &st) != 0) return {};
      env = "JOURNAL_STREAM=" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino) + " ";
    }
    CliResult r = laserline::test_support::run_command(env + LASERLINED_PATH + " " + args + " >>" +
                                                       out + " 2>&1" + shell_after);
    std::ifstream in(out);
    r.out.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    return r;
  }
  std::string out_file() const { return (dir_ / "out.txt").string(); }
};

TEST_F(JournalPriorities, ErrorsAndInformationCarryTheirLevel) {
  std::ofstream(out_file()).close();
  CliResult r = run_to_file("--config /nonexistent/x.yaml", out_file());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out,
            "<3>laserlined: /nonexistent/x.yaml: cannot be opened for reading: No such file or "
            "directory\n");

  const std::string good = file("good.yaml", "laser: {mode: alternate}\n");
  r = run_to_file("--check-config --config " + good, out_file());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out, "<6>laserlined: " + good + ": configuration is valid\n");

  // The command line's errors go through the same log.
  r = run_to_file("--frobnicate", out_file());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "<3>laserlined: unknown option '--frobnicate' (see --help)\n");
}

// A stop by a signal that is no request to stop (exit status 128 + its number) is a warning.
TEST_F(JournalPriorities, StopByAFailureSignalIsAWarning) {
  const std::string config = file("run.yaml", "lcm: {url: 'memq://'}\n");
  std::ofstream(out_file()).close();
  const CliResult r =
      run_to_file("--config " + config, out_file(),
                  " & pid=$!; for i in $(seq 200); do grep -q running " + out_file() +
                      " && break; sleep 0.05; done; kill -USR1 $pid; wait $pid");
  EXPECT_EQ(r.exit_code, 128 + SIGUSR1) << r.out;
  EXPECT_EQ(r.out.rfind("<6>laserlined: running sim camera", 0), 0u) << r.out;
  EXPECT_NE(r.out.find("\n<4>laserlined: stopped (SIGUSR1) after "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\n<6>laserlined: laser sim: "), std::string::npos) << r.out;
}

TEST_F(JournalPriorities, NoPrefixOutsideTheJournal) {
  // No JOURNAL_STREAM: a terminal, a file, a pipe.
  CliResult r = run_to_file("--config /nonexistent/x.yaml");
  EXPECT_EQ(r.out,
            "laserlined: /nonexistent/x.yaml: cannot be opened for reading: No such file or "
            "directory\n");
  // JOURNAL_STREAM inherited, but stderr redirected elsewhere: not the journal's stream.
  r = run_to_file("--config /nonexistent/x.yaml", file("other.txt", ""));
  EXPECT_EQ(r.out,
            "laserlined: /nonexistent/x.yaml: cannot be opened for reading: No such file or "
            "directory\n");
  r = laserline::test_support::run_command(
      "JOURNAL_STREAM=garbage " + std::string(LASERLINED_PATH) + " --config /nonexistent/x.yaml");
  EXPECT_EQ(r.out.rfind("laserlined: ", 0), 0u) << r.out;
}

}  // namespace

namespace {

TEST_F(LaserlinedCli, ProbeAndOfflineGoWithCheckConfig) {
  CliResult r = run("--offline");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserlined: --offline goes with --check-config\n");
  r = run("--probe");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserlined: --probe goes with --check-config\n");
  r = run("--check-config --probe --offline");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserlined: --offline and --probe contradict each other\n");
}

// The simulated backends have nothing to find: --probe passes them.
TEST_F(LaserlinedCli, ProbeOfTheSimulatedScanner) {
  const CliResult r = run("--check-config --probe");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out,
            "laserlined: built-in default: configuration is valid, its hardware is "
            "there\n");
}

}  // namespace
