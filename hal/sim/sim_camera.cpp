#include "hal/sim/sim_camera.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "hal/clock.hpp"

namespace laserline::hal {

SimCamera::SimCamera(const SimSceneOptions& options, const Laser* laser, SimCameraStall stall,
                     const LaserChannel& channel, SimCameraExposure exposure)
    : scene_(options),
      laser_(laser),
      stall_(stall),
      exposure_(exposure),
      configured_exposure_(exposure),
      period_ns_(static_cast<std::int64_t>(std::llround(1e9 / options.frame_rate_hz))) {
  if (options.colour != SimColour::kMono) {
    const FrameFormat f = scene_.format();
    converter_ = PixelConverter(scene_.raw_format(), f.width, f.height, channel);
    raw_.assign(scene_.raw_bytes(), 0);
  }
  update_brightness();
}

void SimCamera::update_brightness() {
  const double factor = exposure_.exposure_us / configured_exposure_.exposure_us *
                        std::pow(10.0, (exposure_.gain_db - configured_exposure_.gain_db) / 20.0);
  scaled_ = factor != 1.0;
  for (int level = 0; level < 256; ++level) {
    brightness_[static_cast<std::size_t>(level)] =
        static_cast<std::uint8_t>(std::min(255.0, std::round(level * factor)));
  }
}

std::string SimCamera::check_setting(const CameraSetting& setting) const {
  const std::string name = setting.name;
  if (name == "exposure_us") {
    return range_problem(setting.name, setting.value, setting.number, kSimExposureRange);
  }
  if (name == "gain_db") {
    return range_problem(setting.name, setting.value, setting.number, kSimGainRange);
  }
  if (name == "frame_rate_hz") {
    return "frame_rate_hz: the simulated camera's frame rate is its scene's time base, fixed at "
           "start (camera.frame_rate_hz)";
  }
  return name + ": not a setting of the simulated camera (exposure_us, gain_db)";
}

void SimCamera::apply_setting(const CameraSetting& setting, SettingResult& result) {
  double* value = std::strcmp(setting.name, "exposure_us") == 0 ? &exposure_.exposure_us
                  : std::strcmp(setting.name, "gain_db") == 0   ? &exposure_.gain_db
                                                                : nullptr;
  if (value == nullptr) {
    result.accepted = false;
    write_setting_text(result.reason, "not a setting of the simulated camera");
    return;
  }
  write_setting_value(result.old_value, *value);
  *value = setting.number;
  update_brightness();
  write_setting_value(result.in_force, *value);
  result.accepted = true;
}

bool SimCamera::read_setting(const char* name, std::span<char> value) {
  if (std::strcmp(name, "exposure_us") == 0) {
    write_setting_value(value, exposure_.exposure_us);
  } else if (std::strcmp(name, "gain_db") == 0) {
    write_setting_value(value, exposure_.gain_db);
  } else if (std::strcmp(name, "frame_rate_hz") == 0) {
    write_setting_value(value, 1e9 / static_cast<double>(period_ns_));
  } else {
    return false;
  }
  return true;
}

bool SimCamera::open(std::string* /*error*/) {
  start_mono_ns_ = monotonic_ns();
  next_sequence_ = 0;
  stopped_.store(false, std::memory_order_release);
  return true;
}

GrabStatus SimCamera::grab(std::span<std::uint8_t> dst, FrameInfo& info,
                           std::chrono::milliseconds timeout) {
  if (stopped_.load(std::memory_order_acquire)) return GrabStatus::kStopped;
  if (dst.size() < scene_.format().bytes()) return GrabStatus::kError;
  // A free-running sensor: frame n starts exposing at start + n * period. When the consumer is
  // late the frames it missed are lost (sequence numbers jump), as with a real camera.
  const std::int64_t now = monotonic_ns();
  std::int64_t exposure = start_mono_ns_ + static_cast<std::int64_t>(next_sequence_) * period_ns_;
  if (exposure < now - period_ns_) {
    const auto missed = static_cast<std::uint64_t>((now - exposure) / period_ns_);
    next_sequence_ += missed;
    exposure += static_cast<std::int64_t>(missed) * period_ns_;
  }
  if (stall_.after_s > 0) {
    // Frames due inside the stall window never come; the ones after it do.
    const std::int64_t stall_begin =
        start_mono_ns_ + static_cast<std::int64_t>(stall_.after_s * 1e9);
    const std::int64_t stall_end = stall_begin + static_cast<std::int64_t>(stall_.for_s * 1e9);
    if (exposure >= stall_begin && exposure < stall_end) {
      const auto skipped =
          static_cast<std::uint64_t>((stall_end - exposure + period_ns_ - 1) / period_ns_);
      next_sequence_ += skipped;
      exposure += static_cast<std::int64_t>(skipped) * period_ns_;
    }
  }
  if (exposure > now + timeout.count() * 1'000'000) {
    if (!sleep_until(now + timeout.count() * 1'000'000, stopped_)) return GrabStatus::kStopped;
    return GrabStatus::kTimeout;
  }
  if (!sleep_until(exposure, stopped_)) return GrabStatus::kStopped;

  render_frame(next_sequence_, laser_ != nullptr && laser_->is_on(), dst, info);
  info.sequence = next_sequence_;
  info.camera_ns = exposure - start_mono_ns_;
  info.exposure_mono_ns = exposure;
  info.arrival_mono_ns = monotonic_ns();
  info.arrival_wall_ns = wall_ns();
  ++next_sequence_;
  return GrabStatus::kOk;
}

void SimCamera::render_frame(std::uint64_t sequence, bool laser_on, std::span<std::uint8_t> dst,
                             FrameInfo& info) {
  if (raw_.empty()) {
    scene_.render(sequence, laser_on, dst);
  } else {
    scene_.render(sequence, laser_on, raw_);
    const FrameFormat f = scene_.format();
    converter_.convert(raw_.data(), raw_.size() / static_cast<std::size_t>(f.height), dst.data(),
                       static_cast<std::size_t>(f.stride));
  }
  if (scaled_) {
    for (std::uint8_t& pixel : dst.first(scene_.format().bytes()))
      pixel = brightness_[pixel];
  }
  info.sequence = sequence;
  info.laser_on = laser_on;
  info.exposure_us = exposure_.exposure_us;
  info.gain_db = exposure_.gain_db;
}

void SimCamera::stop() {
  stopped_.store(true, std::memory_order_release);
}

}  // namespace laserline::hal
