// The strobe's exposure history, the matching of frames to exposures and the laser's state over
// an exposure, each frame's laser state from them (hal/exposure_strobe.hpp), without hardware. The
// GPIO reader and the frame path with them: test_strobe.cpp.
#include "hal/exposure_strobe.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

namespace laserline::hal {
namespace {

constexpr std::int64_t kMs = 1'000'000;

TEST(ExposureHistory, KeepsTheLastExposuresFromTheirEdges) {
  ExposureHistory history(4);
  history.end(5 * kMs);  // opened mid-exposure: no start, ignored
  EXPECT_EQ(history.completed(), 0u);
  EXPECT_EQ(history.last_edge_mono_ns(), 5 * kMs);
  for (std::int64_t i = 0; i < 6; ++i) {
    history.begin((10 + 10 * i) * kMs);
    history.end((12 + 10 * i) * kMs);
  }
  EXPECT_EQ(history.completed(), 6u);
  ExposureInterval interval;
  EXPECT_FALSE(history.get(1, &interval)) << "overwritten: only the last 4 are kept";
  ASSERT_TRUE(history.get(2, &interval));
  EXPECT_EQ(interval.index, 2u);
  EXPECT_EQ(interval.start_mono_ns, 30 * kMs);
  EXPECT_EQ(interval.end_mono_ns, 32 * kMs);
  EXPECT_FALSE(history.get(6, &interval)) << "not complete yet";
  history.begin(70 * kMs);
  history.begin(71 * kMs);  // a missed end: the later start counts
  history.end(72 * kMs);
  ASSERT_TRUE(history.get(6, &interval));
  EXPECT_EQ(interval.start_mono_ns, 71 * kMs);
}

// One writer, one reader hammering it: every exposure read is one the writer wrote whole.
TEST(ExposureHistory, ReadersNeverSeeATornExposure) {
  ExposureHistory history(8);
  std::atomic<bool> done{false};
  std::atomic<std::int64_t> reads{0};
  std::thread writer([&] {
    // On a loaded machine the reader may not run at all during the first 50,000: the writer goes
    // on until the reader has read some whole (a bounded wait).
    for (std::int64_t i = 1;
         i <= 50'000 || (reads.load(std::memory_order_relaxed) < 100 && i <= 50'000'000); ++i) {
      history.begin(i * 1000);
      history.end(i * 1000 + 7);
      if (i % 16 == 0) std::this_thread::yield();  // the reader gets to read some whole
    }
    done = true;
  });
  while (!done) {
    const std::uint64_t n = history.completed();
    ExposureInterval interval;
    if (n > 0 && history.get(n - 1, &interval)) {
      ASSERT_EQ(interval.end_mono_ns - interval.start_mono_ns, 7);
      ASSERT_EQ(interval.start_mono_ns, static_cast<std::int64_t>(interval.index + 1) * 1000);
      reads.fetch_add(1, std::memory_order_relaxed);
    }
  }
  writer.join();
  EXPECT_GT(reads.load(), 0);
}

// Exposures every 10 ms, 2 ms long, from t = 100 ms; the camera's clock runs 5 s ahead.
void fill(ExposureHistory& history, int count, std::int64_t first_ms = 100) {
  for (int i = 0; i < count; ++i) {
    history.begin((first_ms + 10 * i) * kMs);
    history.end((first_ms + 10 * i + 2) * kMs);
  }
}
constexpr std::int64_t kCameraAhead = 5'000 * kMs;

TEST(ExposureMatcher, ByOrderFirstThenByTheCamerasClockAcrossLostFrames) {
  ExposureHistory history(16);
  fill(history, 6);
  ExposureMatcher matcher;
  ExposureInterval interval;
  // The first frame: the oldest exposure (its end before the arrival), whatever its timestamp.
  ASSERT_TRUE(matcher.match(history, 100 * kMs + kCameraAhead, 110 * kMs, 2 * kMs, &interval));
  EXPECT_EQ(interval.index, 0u);
  // Frames 1 and 2 were lost by the camera: frame 3 is 30 ms later on its clock.
  ASSERT_TRUE(matcher.match(history, 130 * kMs + kCameraAhead, 140 * kMs, 2 * kMs, &interval));
  EXPECT_EQ(interval.index, 3u);
  EXPECT_EQ(interval.start_mono_ns, 130 * kMs);
  EXPECT_EQ(interval.end_mono_ns, 132 * kMs);
  // An exposure whose end is after the frame's arrival cannot be its exposure.
  EXPECT_FALSE(matcher.match(history, 140 * kMs + kCameraAhead, 141 * kMs, 2 * kMs, &interval));
  // Nothing near the prediction (frame 6's edges not read yet): not matched; the next frame is
  // matched by its clock again.
  EXPECT_FALSE(matcher.match(history, 160 * kMs + kCameraAhead, 170 * kMs, 2 * kMs, &interval));
  fill(history, 2, 160);  // exposures 6, 7 at 160 and 170 ms
  ASSERT_TRUE(matcher.match(history, 170 * kMs + kCameraAhead, 180 * kMs, 2 * kMs, &interval));
  EXPECT_EQ(interval.start_mono_ns, 170 * kMs);
}

TEST(ExposureMatcher, RestartTakesTheOrderAgainFromTheNextExposure) {
  ExposureHistory history(16);
  fill(history, 3);
  ExposureMatcher matcher;
  ExposureInterval interval;
  ASSERT_TRUE(matcher.match(history, 100 * kMs, 110 * kMs, 2 * kMs, &interval));
  matcher.restart(history);  // frames stopped; the camera's clock may start again
  fill(history, 2, 500);
  ASSERT_TRUE(matcher.match(history, 7 * kMs, 520 * kMs, 2 * kMs, &interval));
  EXPECT_EQ(interval.start_mono_ns, 500 * kMs);
  ASSERT_TRUE(matcher.match(history, 17 * kMs, 520 * kMs, 2 * kMs, &interval));
  EXPECT_EQ(interval.start_mono_ns, 510 * kMs);
}

TEST(ExposureMatcher, ASilentStrobeMatchesNothing) {
  ExposureHistory history(16);
  ExposureMatcher matcher;
  ExposureInterval interval;
  for (int i = 0; i < 5; ++i)
    EXPECT_FALSE(matcher.match(history, i * 10 * kMs, i * 10 * kMs + 5, 2 * kMs, &interval));
}

TEST(LaserSwitchHistory, OnOffOrMixedOverAnExposure) {
  LaserSwitchHistory switches;
  EXPECT_EQ(switches.during(0, 10), LaserExposure::kOff) << "opened off";
  switches.add({true, 100, 0});
  switches.add({false, 200, 1});
  EXPECT_EQ(switches.during(110, 190), LaserExposure::kOn);
  EXPECT_EQ(switches.during(10, 90), LaserExposure::kOff);
  EXPECT_EQ(switches.during(90, 110), LaserExposure::kMixed) << "switched on inside it";
  EXPECT_EQ(switches.during(190, 210), LaserExposure::kMixed) << "switched off inside it";
  EXPECT_EQ(switches.during(50, 250), LaserExposure::kMixed);
  EXPECT_EQ(switches.during(210, 300), LaserExposure::kOff);
  EXPECT_EQ(switches.during(100, 150), LaserExposure::kOn) << "a switch at the start edge";
  for (int i = 0; i < 20; ++i)
    switches.add({i % 2 == 0, 1000 + 100 * i, static_cast<std::uint64_t>(2 + i)});
  EXPECT_EQ(switches.during(150, 160), LaserExposure::kUnknown) << "older than the switches kept";
  EXPECT_EQ(switches.during(2810, 2890), LaserExposure::kOn);  // after the switch at 2800 (on)
}

// Without a strobe each frame's laser state stays the estimate, and its own switch is late when it
// came after the camera's timestamp of the exposure (the strobe's exact case: test_strobe.cpp).
TEST(FrameLaserDecider, WithoutAStrobeTheCamerasTimestampDecidesLateSwitches) {
  FrameLaserDecider decider(nullptr, 100.0);
  FrameInfo info;
  info.laser_on = true;
  info.exposure_mono_ns = 50 * kMs;
  info.exposure_start_mono_ns = 7;  // left from an earlier frame in the slot
  FrameLaserDecider::Decision decided = decider.decide(info, 0);
  EXPECT_FALSE(decided.matched);
  EXPECT_FALSE(decided.late_switch) << "no switch yet";
  EXPECT_EQ(info.exposure_start_mono_ns, 0);
  decider.switched({true, 60 * kMs, 1});
  decided = decider.decide(info, 1);
  EXPECT_TRUE(decided.late_switch) << "switched for this frame after its exposure began";
  EXPECT_EQ(info.laser_switch_mono_ns, 60 * kMs);
  EXPECT_TRUE(info.laser_on) << "the estimate is the switch's intent";
  info.exposure_mono_ns = 70 * kMs;
  EXPECT_FALSE(decider.decide(info, 1).late_switch) << "switched before the exposure";
  EXPECT_FALSE(decider.decide(info, 2).late_switch) << "an earlier frame's switch";
}

}  // namespace
}  // namespace laserline::hal
