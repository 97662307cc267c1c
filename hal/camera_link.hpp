#pragma once

#include <atomic>
#include <cstdint>

#include "hal/camera.hpp"

namespace laserline::hal {

// The pieces every camera backend on a link that can fail (a network, a USB cable) shares.

// Maps a camera's own timestamps to host CLOCK_MONOTONIC: offset = minimum over frames of (host
// arrival - camera time), so the frame with the least transfer delay defines it; the minimum rises
// by kDriftNsPerFrame a frame so that it follows drift between the clocks. The mapped time is late
// by the shortest transfer delay seen (readout + link), constant for a given format.
// Thread context: the camera thread.
class CameraClockOffset {
 public:
  // 1 µs per frame is 100 ppm at 10 Hz, far above crystal drift, and small against the transfer
  // delays the minimum filters.
  static constexpr std::int64_t kDriftNsPerFrame = 1000;

  // Forgets the offset: the next frame defines it again (a new stream, a reopened device).
  void reset() { valid_ = false; }
  // The host monotonic time of `camera_ns`, given the frame arrived at `arrival_mono_ns`.
  std::int64_t to_monotonic(std::int64_t camera_ns, std::int64_t arrival_mono_ns);

 private:
  std::int64_t offset_ns_ = 0;
  bool valid_ = false;
};

// Our frame sequence from a device's own frame counter: consecutive from 0 over the whole run,
// across reconnects (after which the device may count from anywhere) and across the counter's
// wrap. A gap in the counter is frames the device numbered but never delivered.
// Thread context: the camera thread.
class DeviceSequence {
 public:
  // `wrap`: the counter's largest value, after which it starts again at 1 (GigE Vision 1's 16-bit
  // frame id: 65535); 0: it does not wrap.
  explicit DeviceSequence(std::uint64_t wrap = 0) : wrap_(wrap) {}

  // A fresh start (open()): the next frame is 0.
  void reset() {
    next_ = 0;
    restart();
  }
  // A new stream (a reconnect): the next frame continues our sequence, whatever its counter.
  void restart() { have_counter_ = false; }
  // Our sequence number of the frame the device numbered `counter`; `skipped` is how many frames
  // the device numbered since the previous one without delivering them.
  std::uint64_t next(std::uint64_t counter, std::int64_t& skipped);

 private:
  std::uint64_t wrap_;
  std::int64_t base_ = 0;  // our sequence - the device's counter
  std::uint64_t next_ = 0;
  std::uint64_t last_counter_ = 0;
  bool have_counter_ = false;
};

// When to try again after a camera was lost: first after min_ms, then after twice as long each
// failed try, up to max_ms; back to min_ms once a try succeeded. Reconnecting allocates (driver
// objects): only on this recovery path. Thread context: the camera thread.
class ReconnectBackoff {
 public:
  ReconnectBackoff() = default;
  ReconnectBackoff(int min_ms, int max_ms) : min_ms_(min_ms), max_ms_(max_ms), delay_ms_(min_ms) {}

  // Sleeps (in slices of kWaitSliceMs, so that `stopped` is noticed) until the next try is due
  // (kOk) or `deadline_mono_ns` passes (kTimeout), whichever comes first; kStopped once `stopped`.
  GrabStatus wait(std::int64_t deadline_mono_ns, const std::atomic<bool>& stopped) const;
  // The link was lost now: the next try is due after the current delay.
  void lost();
  // A try failed: the next is due after the current delay, which then doubles.
  void failed();
  // A try succeeded: the delay is min_ms again.
  void succeeded() { delay_ms_ = min_ms_; }
  // A fresh start (open()).
  void reset() { delay_ms_ = min_ms_; }

  static constexpr std::int64_t kWaitSliceMs = 50;

 private:
  int min_ms_ = 100;
  int max_ms_ = 2000;
  int delay_ms_ = 100;
  std::int64_t next_try_mono_ns_ = 0;
};

// CameraHealth's counters as the camera thread counts them and any thread reads them.
struct CameraHealthCounters {
  std::atomic<std::int64_t> missing_packets{0};
  std::atomic<std::int64_t> timeouts{0};
  std::atomic<std::int64_t> size_mismatches{0};
  std::atomic<std::int64_t> underruns{0};
  std::atomic<std::int64_t> other_errors{0};
  std::atomic<std::int64_t> reconnects{0};
  std::atomic<std::int64_t> skipped_frames{0};

  static void add(std::atomic<std::int64_t>& counter, std::int64_t n = 1) {
    counter.fetch_add(n, std::memory_order_relaxed);
  }
  CameraHealth load() const;
};

}  // namespace laserline::hal
