#include "hal/exposure_strobe.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace laserline::hal {

ExposureHistory::ExposureHistory(std::size_t capacity)
    : slots_(new Slot[capacity]), mask_(capacity - 1) {
  if (capacity < 2 || (capacity & (capacity - 1)) != 0) {
    throw std::invalid_argument("ExposureHistory capacity must be a power of two >= 2");
  }
}

void ExposureHistory::begin(std::int64_t mono_ns) {
  open_start_ = mono_ns;
  last_edge_.store(mono_ns, std::memory_order_release);
}

void ExposureHistory::end(std::int64_t mono_ns) {
  last_edge_.store(mono_ns, std::memory_order_release);
  if (open_start_ == 0) return;
  const std::uint64_t index = completed_.load(std::memory_order_relaxed);
  Slot& slot = slots_[index & mask_];
  // Boehm's seqlock without fences (ThreadSanitizer has none): the data's release stores carry
  // the odd sequence to a reader that sees them, so it finds the sequence changed.
  slot.sequence.store(2 * index + 1, std::memory_order_relaxed);
  slot.start.store(open_start_, std::memory_order_release);
  slot.end.store(mono_ns, std::memory_order_release);
  slot.sequence.store(2 * (index + 1), std::memory_order_release);
  completed_.store(index + 1, std::memory_order_release);
  open_start_ = 0;
}

bool ExposureHistory::get(std::uint64_t index, ExposureInterval* out) const {
  if (index >= completed()) return false;
  const Slot& slot = slots_[index & mask_];
  const std::uint64_t expected = 2 * (index + 1);
  if (slot.sequence.load(std::memory_order_acquire) != expected) return false;
  const std::int64_t start = slot.start.load(std::memory_order_acquire);
  const std::int64_t end = slot.end.load(std::memory_order_acquire);
  if (slot.sequence.load(std::memory_order_relaxed) != expected) return false;  // overwritten
  *out = ExposureInterval{index, start, end};
  return true;
}

bool ExposureMatcher::match(const ExposureHistory& history, std::int64_t camera_ns,
                            std::int64_t arrival_mono_ns, std::int64_t tolerance_ns,
                            ExposureInterval* out) {
  const std::uint64_t completed = history.completed();
  const std::uint64_t oldest_kept =
      completed > history.capacity() ? completed - history.capacity() : 0;
  if (next_index_ < oldest_kept) next_index_ = oldest_kept;
  auto take = [&](const ExposureInterval& interval) {
    anchored_ = true;
    misses_ = 0;
    next_index_ = interval.index + 1;
    last_camera_ns_ = camera_ns;
    last_start_ns_ = interval.start_mono_ns;
    *out = interval;
    return true;
  };
  ExposureInterval interval;
  if (!anchored_) {
    // By order: one exposure per frame, so frames that went unmatched since the last match
    // had the exposures before this one; at most the newest (a strobe that came alive late).
    if (completed == 0) return false;
    const std::uint64_t index =
        std::min(next_index_ + static_cast<std::uint64_t>(misses_), completed - 1);
    if (history.get(index, &interval) && interval.end_mono_ns <= arrival_mono_ns) {
      return take(interval);
    }
    ++misses_;
    return false;
  }
  const std::int64_t predicted = last_start_ns_ + (camera_ns - last_camera_ns_);
  bool found = false;
  ExposureInterval best;
  for (std::uint64_t i = next_index_; i < completed; ++i) {
    if (!history.get(i, &interval)) continue;
    if (interval.start_mono_ns > predicted + tolerance_ns) break;  // later ones start later
    const std::int64_t off = std::llabs(interval.start_mono_ns - predicted);
    if (off <= tolerance_ns && interval.end_mono_ns <= arrival_mono_ns &&
        (!found || off < std::llabs(best.start_mono_ns - predicted))) {
      best = interval;
      found = true;
    }
  }
  if (found) return take(best);
  if (++misses_ >= 3) anchored_ = false;
  return false;
}

void ExposureMatcher::restart(const ExposureHistory& history) {
  anchored_ = false;
  misses_ = 0;
  next_index_ = history.completed();
}

void LaserSwitchHistory::add(const LaserSwitch& record) {
  switches_[count_ % kKept] = record;
  ++count_;
}

LaserExposure LaserSwitchHistory::during(std::int64_t start_mono_ns,
                                         std::int64_t end_mono_ns) const {
  const std::size_t kept = count_ < kKept ? count_ : kKept;
  // Oldest first: the state at the exposure's start, then any change inside it.
  bool on = false;
  bool known = count_ <= kKept;  // nothing forgotten: before the first switch it was off
  bool changed = false;
  for (std::size_t k = 0; k < kept; ++k) {
    const LaserSwitch& s = switches_[(count_ - kept + k) % kKept];
    if (s.mono_ns <= start_mono_ns) {
      on = s.on;
      known = true;
    } else if (s.mono_ns < end_mono_ns) {
      changed = changed || s.on != on;
      on = s.on;
    }
  }
  if (!known) return LaserExposure::kUnknown;
  if (changed) return LaserExposure::kMixed;
  return on ? LaserExposure::kOn : LaserExposure::kOff;
}

FrameLaserDecider::FrameLaserDecider(const ExposureStrobe* strobe, double frame_rate_hz)
    : strobe_(strobe), tolerance_ns_(static_cast<std::int64_t>(0.25e9 / frame_rate_hz)) {}

void FrameLaserDecider::switched(const LaserSwitch& record) {
  last_switch_ = record;
  switches_.add(record);
}

FrameLaserDecider::Decision FrameLaserDecider::decide(FrameInfo& info, std::uint64_t grab_index) {
  Decision decision;
  info.laser_switch_mono_ns = last_switch_.mono_ns;
  info.exposure_start_mono_ns = 0;
  info.exposure_end_mono_ns = 0;
  const bool own_switch = last_switch_.for_frame == grab_index && last_switch_.mono_ns != 0;
  ExposureInterval exposure;
  if (strobe_ != nullptr && matcher_.match(strobe_->history(), info.camera_ns, info.arrival_mono_ns,
                                           tolerance_ns_, &exposure)) {
    info.exposure_start_mono_ns = exposure.start_mono_ns;
    info.exposure_end_mono_ns = exposure.end_mono_ns;
    const LaserExposure lit = switches_.during(exposure.start_mono_ns, exposure.end_mono_ns);
    if (lit != LaserExposure::kUnknown) info.laser_on = lit != LaserExposure::kOff;
    decision.matched = true;
    decision.late_switch = lit == LaserExposure::kMixed ||
                           (own_switch && last_switch_.mono_ns > exposure.start_mono_ns);
  } else {
    decision.late_switch = own_switch && last_switch_.mono_ns > info.exposure_mono_ns;
  }
  return decision;
}

void FrameLaserDecider::frames_stopped() {
  if (strobe_ != nullptr) matcher_.restart(strobe_->history());
}

void describe_strobe_health(const ExposureStrobe& strobe, double frame_rate_hz,
                            std::int64_t now_mono, std::int64_t matched, std::int64_t unmatched,
                            char* out, std::size_t size) {
  if (size == 0) return;
  const char* what = strobe.describe().c_str();
  const std::int64_t last_edge = strobe.history().last_edge_mono_ns();
  const auto silent_ns =
      std::max<std::int64_t>(1'000'000'000, static_cast<std::int64_t>(3e9 / frame_rate_hz));
  constexpr const char* kFallback = "laser state from the camera's timestamps (estimate)";
  if (last_edge == 0) {
    std::snprintf(out, size, "silent: no edge on %s since start; %s", what, kFallback);
  } else if (now_mono - last_edge > silent_ns) {
    std::snprintf(out, size, "silent: no edge on %s for %.1f s; %s", what,
                  static_cast<double>(now_mono - last_edge) * 1e-9, kFallback);
  } else if (unmatched > 0) {
    std::snprintf(out, size, "%lld of %lld frames not matched to an exposure on %s; %s",
                  static_cast<long long>(unmatched), static_cast<long long>(matched + unmatched),
                  what, kFallback);
  } else {
    std::snprintf(out, size, "ok");
  }
}

}  // namespace laserline::hal
