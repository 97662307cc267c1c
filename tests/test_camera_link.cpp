#include "hal/camera_link.hpp"

#include <gtest/gtest.h>

#include "hal/clock.hpp"

namespace laserline::hal {
namespace {

TEST(CameraClockOffset, TheLeastDelayedFrameDefinesTheOffsetWhichRisesSlowly) {
  CameraClockOffset clock;
  constexpr std::int64_t kDrift = CameraClockOffset::kDriftNsPerFrame;
  // Camera time 1000 arrives at host 5000: offset 4000.
  EXPECT_EQ(clock.to_monotonic(1000, 5000), 1000 + 4000);
  // A frame delayed more does not move it but for the drift allowance.
  EXPECT_EQ(clock.to_monotonic(2000, 9000), 2000 + 4000 + kDrift);
  // A frame delayed less lowers it at once.
  EXPECT_EQ(clock.to_monotonic(3000, 5500), 3000 + 2500);
  clock.reset();
  EXPECT_EQ(clock.to_monotonic(3000, 9000), 3000 + 6000) << "a reset forgets the offset";
}

TEST(DeviceSequence, ConsecutiveAcrossRestartsWithGapsCounted) {
  DeviceSequence sequence;
  std::int64_t skipped = -1;
  EXPECT_EQ(sequence.next(40, skipped), 0u) << "the first frame is 0 whatever its counter";
  EXPECT_EQ(skipped, 0);
  EXPECT_EQ(sequence.next(41, skipped), 1u);
  EXPECT_EQ(skipped, 0);
  EXPECT_EQ(sequence.next(45, skipped), 5u) << "42 to 44 numbered, not delivered";
  EXPECT_EQ(skipped, 3);
  // A reopened device counts from the start: ours goes on.
  sequence.restart();
  EXPECT_EQ(sequence.next(0, skipped), 6u);
  EXPECT_EQ(skipped, 0);
  EXPECT_EQ(sequence.next(2, skipped), 8u);
  EXPECT_EQ(skipped, 1);
  // A counter that does not wrap is taken as it is, however far it falls back.
  EXPECT_EQ(sequence.next(1, skipped), 7u);
  EXPECT_EQ(skipped, 0);
  sequence.reset();
  EXPECT_EQ(sequence.next(9, skipped), 0u) << "a fresh start";
}

TEST(DeviceSequence, SixteenBitFrameIdWrapsFrom65535To1) {
  DeviceSequence sequence(65535);
  std::int64_t skipped = -1;
  EXPECT_EQ(sequence.next(65534, skipped), 0u);
  EXPECT_EQ(sequence.next(65535, skipped), 1u);
  EXPECT_EQ(sequence.next(1, skipped), 2u) << "GigE Vision 1 skips 0";
  EXPECT_EQ(skipped, 0);
  EXPECT_EQ(sequence.next(3, skipped), 4u);
  EXPECT_EQ(skipped, 1);
  // Across the wrap with frames lost on both sides of it.
  for (std::uint64_t id = 4; id <= 65533; ++id)
    sequence.next(id, skipped);
  EXPECT_EQ(sequence.next(2, skipped), 65535u + 3u);
  EXPECT_EQ(skipped, 3) << "65534, 65535 and 1 lost";
  // A step back of half the range or less is no wrap.
  EXPECT_EQ(sequence.next(32770, skipped), 65535u + 32770u + 1u);
  EXPECT_EQ(sequence.next(2, skipped), 65535u + 3u);
  EXPECT_EQ(skipped, 0);
}

TEST(ReconnectBackoff, DoublesUpToTheMaximumAndWaitsUntilDue) {
  constexpr std::int64_t kMs = 1'000'000;
  ReconnectBackoff backoff(20, 50);
  const std::atomic<bool> not_stopped{false};
  const std::atomic<bool> stopped{true};
  backoff.lost();
  EXPECT_EQ(backoff.wait(monotonic_ns() + kMs, not_stopped), GrabStatus::kTimeout);
  EXPECT_EQ(backoff.wait(monotonic_ns() + 1000 * kMs, stopped), GrabStatus::kStopped);
  // Each failed try waits twice as long as the one before, up to the maximum.
  for (const std::int64_t delay_ms : {20, 40, 50, 50}) {
    const std::int64_t start = monotonic_ns();
    backoff.failed();
    EXPECT_EQ(backoff.wait(start + 1000 * kMs, not_stopped), GrabStatus::kOk);
    const std::int64_t waited = monotonic_ns() - start;
    EXPECT_GE(waited, delay_ms * kMs);
    EXPECT_LT(waited, (delay_ms + 500) * kMs);
  }
  backoff.succeeded();
  const std::int64_t start = monotonic_ns();
  backoff.lost();
  EXPECT_EQ(backoff.wait(start + 1000 * kMs, not_stopped), GrabStatus::kOk);
  EXPECT_LT(monotonic_ns() - start, 40 * kMs + 500 * kMs);
  EXPECT_GE(monotonic_ns() - start, 20 * kMs) << "back to the minimum after a success";
}

TEST(CameraHealthCounters, LoadReadsEveryCounter) {
  CameraHealthCounters counters;
  CameraHealthCounters::add(counters.missing_packets, 2);
  CameraHealthCounters::add(counters.timeouts);
  CameraHealthCounters::add(counters.size_mismatches, 3);
  CameraHealthCounters::add(counters.underruns, 4);
  CameraHealthCounters::add(counters.other_errors, 5);
  CameraHealthCounters::add(counters.reconnects, 6);
  CameraHealthCounters::add(counters.skipped_frames, 7);
  const CameraHealth h = counters.load();
  EXPECT_EQ(h.missing_packets, 2);
  EXPECT_EQ(h.timeouts, 1);
  EXPECT_EQ(h.size_mismatches, 3);
  EXPECT_EQ(h.underruns, 4);
  EXPECT_EQ(h.other_errors, 5);
  EXPECT_EQ(h.reconnects, 6);
  EXPECT_EQ(h.skipped_frames, 7);
}

}  // namespace
}  // namespace laserline::hal
