// laserline-listen on a live bus (a private network namespace): what it says when nothing comes,
// and that exposure times far older than the receive time are not reported as latency.
#include <gtest/gtest.h>
#include <laserline/profile_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

#include "private_network.hpp"
#include "run_command.hpp"

namespace {

std::string g_namespace_problem;
constexpr const char* kUrl = "udpm://239.255.76.67:7667?ttl=0";

std::int64_t now_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Starts laserline-listen with `args`, publishes `profiles` profiles whose exposure was
// `age_s` ago (one every 50 ms, from half a second after the start), returns what it printed.
laserline::test_support::CommandResult listen(const std::string& args, int profiles, double age_s) {
  std::thread publisher([&] {
    lcm::LCM lcm(kUrl);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    for (int i = 0; i < profiles; ++i) {
      laserline::profile_t p{};
      p.utime = now_us() - static_cast<std::int64_t>(age_s * 1e6);
      p.sequence = i;
      p.width = 320;
      p.height = 240;
      p.detector = "maxvalue";
      lcm.publish("LASERLINE_PROFILE", &p);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  auto r = laserline::test_support::run_command(std::string(LASERLINE_LISTEN_PATH) + " --url '" +
                                                kUrl + "' " + args);
  publisher.join();
  return r;
}

TEST(Listen, SaysOnceWhyNothingMayArrive) {
  if (!g_namespace_problem.empty()) GTEST_SKIP() << g_namespace_problem;
  const auto r = listen("--duration 3.6", 0, 0);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  const std::string warning = "laserline-listen: nothing received on " + std::string(kUrl) +
                              " (LASERLINE_PROFILE, LASERLINE_IMAGE, LASERLINE_STATUS) in 3 s:";
  const auto at = r.out.find(warning);
  ASSERT_NE(at, std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(warning, at + 1), std::string::npos) << "said once: " << r.out;
  const std::string line = r.out.substr(at, r.out.find('\n', at) - at);
  EXPECT_NE(line.find("ttl=1"), std::string::npos) << line;
  EXPECT_NE(line.find("ip route add 224.0.0.0/4 dev"), std::string::npos) << line;
}

TEST(Listen, LiveProfilesGiveTheirLatencyAndNoWarning) {
  if (!g_namespace_problem.empty()) GTEST_SKIP() << g_namespace_problem;
  const auto r = listen("--duration 4", 10, 0.002);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("nothing received"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  latency exposure -> received here: p50 "), std::string::npos) << r.out;
}

// Profiles replayed from a log (lcm-logplayer) carry the dive's exposure times.
TEST(Listen, ReplayedProfilesAreNotGivenAReceiveLatency) {
  if (!g_namespace_problem.empty()) GTEST_SKIP() << g_namespace_problem;
  const auto r = listen("--quiet 1", 10, 60);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("  latency exposure -> received here: not meaningful, the exposure times "
                       "are 60."),
            std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("received here: p50"), std::string::npos) << r.out;
}

}  // namespace

int main(int argc, char** argv) {
  // Before any thread exists: unshare(CLONE_NEWUSER) requires a single-threaded process.
  g_namespace_problem = laserline::test::enter_private_network();
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
