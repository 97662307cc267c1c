#include "hal/camera_link.hpp"

#include <time.h>

#include <algorithm>

#include "hal/clock.hpp"

namespace laserline::hal {

namespace {

constexpr std::int64_t kMs = 1'000'000;

}  // namespace

std::int64_t CameraClockOffset::to_monotonic(std::int64_t camera_ns, std::int64_t arrival_mono_ns) {
  const std::int64_t offset = arrival_mono_ns - camera_ns;
  offset_ns_ = valid_ ? std::min(offset_ns_ + kDriftNsPerFrame, offset) : offset;
  valid_ = true;
  return camera_ns + offset_ns_;
}

std::uint64_t DeviceSequence::next(std::uint64_t counter, std::int64_t& skipped) {
  if (!have_counter_) {
    base_ = static_cast<std::int64_t>(next_) - static_cast<std::int64_t>(counter);
    have_counter_ = true;
  } else if (wrap_ != 0 && counter < last_counter_ && last_counter_ - counter > (wrap_ + 1) / 2 &&
             last_counter_ <= wrap_) {
    base_ += static_cast<std::int64_t>(wrap_);
  }
  last_counter_ = counter;
  const std::uint64_t expected = next_;
  next_ = static_cast<std::uint64_t>(base_ + static_cast<std::int64_t>(counter)) + 1;
  skipped = next_ > expected + 1 ? static_cast<std::int64_t>(next_ - expected - 1) : 0;
  return next_ - 1;
}

GrabStatus ReconnectBackoff::wait(std::int64_t deadline_mono_ns,
                                  const std::atomic<bool>& stopped) const {
  for (std::int64_t now = monotonic_ns(); now < std::min(deadline_mono_ns, next_try_mono_ns_);
       now = monotonic_ns()) {
    if (stopped.load(std::memory_order_acquire)) return GrabStatus::kStopped;
    const std::int64_t ns =
        std::min({kWaitSliceMs * kMs, next_try_mono_ns_ - now, deadline_mono_ns - now});
    const timespec ts{static_cast<time_t>(ns / 1'000'000'000),
                      static_cast<long>(ns % 1'000'000'000)};
    nanosleep(&ts, nullptr);
  }
  return monotonic_ns() < next_try_mono_ns_ ? GrabStatus::kTimeout : GrabStatus::kOk;
}

void ReconnectBackoff::lost() {
  next_try_mono_ns_ = monotonic_ns() + delay_ms_ * kMs;
}

void ReconnectBackoff::failed() {
  lost();
  delay_ms_ = std::min(delay_ms_ * 2, max_ms_);
}

CameraHealth CameraHealthCounters::load() const {
  CameraHealth h;
  h.missing_packets = missing_packets.load(std::memory_order_relaxed);
  h.timeouts = timeouts.load(std::memory_order_relaxed);
  h.size_mismatches = size_mismatches.load(std::memory_order_relaxed);
  h.underruns = underruns.load(std::memory_order_relaxed);
  h.other_errors = other_errors.load(std::memory_order_relaxed);
  h.reconnects = reconnects.load(std::memory_order_relaxed);
  h.skipped_frames = skipped_frames.load(std::memory_order_relaxed);
  return h;
}

}  // namespace laserline::hal
