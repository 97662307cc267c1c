#include "hal/memory_camera.hpp"

#include <unistd.h>

#include <cmath>
#include <cstring>
#include <new>

#include "hal/clock.hpp"
#include "hal/sim/sim_camera.hpp"

namespace laserline::hal {

namespace {

std::string megabytes(std::uint64_t bytes) {
  return std::to_string((bytes + 999'999) / 1'000'000) + " MB";
}

// Memory the frames may take: half of this computer's, the rest left to the frame path and
// everything else.
std::uint64_t memory_for_frames() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page = sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return UINT64_MAX;
  return static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page) / 2;
}

}  // namespace

MemoryCamera::MemoryCamera(const MemoryCameraOptions& options, std::unique_ptr<SimCamera> sim,
                           const Laser* laser)
    : options_(options), sim_(std::move(sim)), laser_(laser), format_(sim_->format()) {}

MemoryCamera::MemoryCamera(const MemoryCameraOptions& options, std::unique_ptr<Camera> recording)
    : options_(options), recording_(std::move(recording)), format_(recording_->format()) {}

MemoryCamera::~MemoryCamera() = default;

bool MemoryCamera::open(std::string* error) {
  stopped_.store(false, std::memory_order_release);
  if (info_.empty()) {
    const std::uint64_t copies = sim_ ? 2 : 1;
    const std::uint64_t need =
        static_cast<std::uint64_t>(options_.frames) * copies * format_.bytes();
    if (need > memory_for_frames()) {
      *error = "camera.memory.frames: " + std::to_string(options_.frames) + " frames of " +
               std::to_string(format_.width) + "x" + std::to_string(format_.height) +
               (sim_ ? " (each with the laser on and off)" : "") + " need " + megabytes(need) +
               ", more than half of this computer's " + megabytes(memory_for_frames() * 2) +
               ": hold fewer frames";
      return false;
    }
    try {
      if (!(sim_ ? render(error) : load(error))) return false;
    } catch (const std::bad_alloc&) {
      *error = "camera.memory.frames: cannot allocate " + megabytes(need) + " for " +
               std::to_string(options_.frames) + " frames: hold fewer frames";
      return false;
    }
  }
  period_ns_ =
      options_.rate_hz > 0 ? static_cast<std::int64_t>(std::llround(1e9 / options_.rate_hz)) : 0;
  next_sequence_ = 0;
  end_sequence_ =
      options_.loops > 0 ? static_cast<std::uint64_t>(options_.loops) * info_.size() : 0;
  skipped_frames_.store(0, std::memory_order_relaxed);
  start_mono_ns_ = 0;  // the first grab starts the clock: nothing is due before the caller asks
  return true;
}

bool MemoryCamera::render(std::string* /*error*/) {
  const auto n = static_cast<std::size_t>(options_.frames);
  lit_.assign(n, std::vector<std::uint8_t>(format_.bytes()));
  unlit_.assign(n, std::vector<std::uint8_t>(format_.bytes()));
  info_.assign(n, FrameInfo{});
  for (std::size_t i = 0; i < n; ++i) {
    FrameInfo unlit_info;
    sim_->render_frame(i, true, lit_[i], info_[i]);
    sim_->render_frame(i, false, unlit_[i], unlit_info);
  }
  return true;
}

bool MemoryCamera::load(std::string* error) {
  if (!recording_->open(error)) return false;
  const auto n = static_cast<std::size_t>(options_.frames);
  lit_.reserve(n);
  info_.reserve(n);
  std::vector<std::uint8_t> pixels(format_.bytes());
  GrabStatus status = GrabStatus::kOk;
  while (info_.size() < n) {
    FrameInfo info;
    status = recording_->grab(pixels, info, std::chrono::milliseconds(1000));
    if (status != GrabStatus::kOk) break;
    lit_.push_back(pixels);
    info_.push_back(info);
  }
  recording_->stop();
  if (info_.empty()) {
    *error = std::string("camera.memory.source: the recording gave no frame to hold (") +
             to_string(status) + ")";
    return false;
  }
  return true;
}

GrabStatus MemoryCamera::grab(std::span<std::uint8_t> dst, FrameInfo& info,
                              std::chrono::milliseconds timeout) {
  if (stopped_.load(std::memory_order_acquire)) return GrabStatus::kStopped;
  if (dst.size() < format_.bytes() || info_.empty()) return GrabStatus::kError;
  const std::int64_t now = monotonic_ns();
  if (start_mono_ns_ == 0) start_mono_ns_ = now;
  if (options_.duration_s > 0 &&
      now - start_mono_ns_ >= static_cast<std::int64_t>(options_.duration_s * 1e9)) {
    return GrabStatus::kStopped;
  }
  std::int64_t exposure = now;
  if (period_ns_ > 0) {
    // A free-running camera: frame n is due at start + n * period. A late caller gets the
    // frames of the last `buffers` periods at once; older ones were overwritten.
    exposure = start_mono_ns_ + static_cast<std::int64_t>(next_sequence_) * period_ns_;
    const std::int64_t behind = exposure < now ? (now - exposure) / period_ns_ : 0;
    if (behind >= options_.buffers) {
      const std::int64_t missed = behind - options_.buffers + 1;
      next_sequence_ += static_cast<std::uint64_t>(missed);
      exposure += missed * period_ns_;
      skipped_frames_.fetch_add(missed, std::memory_order_relaxed);
    }
  }
  if (end_sequence_ > 0 && next_sequence_ >= end_sequence_) return GrabStatus::kStopped;
  if (period_ns_ > 0) {
    const std::int64_t timeout_ns = timeout.count() * 1'000'000;
    if (exposure > now + timeout_ns) {
      if (!sleep_until(now + timeout_ns, stopped_)) return GrabStatus::kStopped;
      return GrabStatus::kTimeout;
    }
    if (!sleep_until(exposure, stopped_)) return GrabStatus::kStopped;
  }

  const std::size_t i = next_sequence_ % info_.size();
  const bool unlit = !unlit_.empty() && (laser_ == nullptr || !laser_->is_on());
  std::memcpy(dst.data(), (unlit ? unlit_[i] : lit_[i]).data(), format_.bytes());
  const FrameInfo& held = info_[i];
  info.sequence = next_sequence_;
  info.camera_ns = exposure - start_mono_ns_;
  info.exposure_mono_ns = exposure;
  info.arrival_mono_ns = monotonic_ns();
  info.arrival_wall_ns = wall_ns();
  info.laser_on = unlit_.empty() ? held.laser_on : !unlit;
  info.exposure_us = held.exposure_us;
  info.gain_db = held.gain_db;
  ++next_sequence_;
  return GrabStatus::kOk;
}

void MemoryCamera::stop() {
  stopped_.store(true, std::memory_order_release);
}

CameraHealth MemoryCamera::health() const {
  CameraHealth h;
  h.skipped_frames = skipped_frames_.load(std::memory_order_relaxed);
  return h;
}

}  // namespace laserline::hal
