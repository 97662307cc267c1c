#pragma once

#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>

#include "daemon/command.hpp"
#include "daemon/command_applier.hpp"
#include "daemon/config.hpp"
#include "daemon/cpu_usage.hpp"
#include "daemon/frame_slots.hpp"
#include "daemon/latency.hpp"
#include "daemon/lcm_publisher.hpp"
#include "daemon/raw_frame_encoder.hpp"
#include "daemon/spsc_ring.hpp"
#include "daemon/worker_pool.hpp"
#include "hal/camera.hpp"
#include "hal/exposure_strobe.hpp"
#include "hal/laser.hpp"
#include "pipeline/detector.hpp"

namespace laserline::daemon {

// Totals of a run, for the log line at exit and for tests.
struct FramePathSummary {
  std::int64_t frames_captured = 0;
  std::int64_t frames_processed = 0;
  std::int64_t frames_dropped = 0;
  std::int64_t profiles_published = 0;
  std::int64_t profiles_dropped = 0;
  std::int64_t images_published = 0;
  std::int64_t images_dropped = 0;  // raw frames lost: image ring full (encoder too slow), stop
  std::int64_t grab_timeouts = 0;
  std::int64_t grab_errors = 0;
  std::int64_t publish_errors = 0;
  std::int64_t laser_safety_offs = 0;
  std::int64_t frames_over_budget = 0;
  std::int64_t laser_switches = 0;
  std::int64_t laser_late_switches = 0;
  std::int64_t strobe_matched = 0;
  std::int64_t strobe_unmatched = 0;
  LatencySummary latency;   // exposure -> profile published
  LatencySummary pipeline;  // frame arrival -> profile published
};

// The whole frame path, wired: camera thread -> SPSC ring -> worker (detector) -> SPSC rings ->
// publisher thread -> LCM. Every buffer is allocated in start(); afterwards the camera and
// worker threads neither allocate nor lock, and the publisher only calls into LCM.
//
// Laser safety: the camera thread switches the laser per frame (mode on/alternate/off), and
// off when a grab times out or fails; it stays off until frames come back. The owner calls
// enforce_laser_safety() periodically from another thread so that the laser goes off even when
// the camera thread is stuck inside the driver. stop() and the destructor switch it off.
//
// Commands (settings changed while running) are carried out by the camera thread between two
// grabs and by the worker between two frames (CommandApplier).
//
// Thread context: construct, start(), stop(), enforce_laser_safety() and summary() from the
// owning (main) thread; submit_command() and take_command_result() from one command thread.
class FramePath {
 public:
  FramePath(const DaemonConfig& config, hal::Camera& camera, hal::Laser& laser,
            pipeline::Detector& detector, lcm::LCM& lcm);
  ~FramePath();
  FramePath(const FramePath&) = delete;
  FramePath& operator=(const FramePath&) = delete;

  // Allocates everything and starts the threads. With config.realtime, also gives them their
  // SCHED_FIFO priorities (thread_priorities.hpp); returns false with the reason in *error when
  // that is refused (everything is stopped again).
  bool start(std::string* error);
  void stop();
  void enforce_laser_safety();
  FramePathSummary summary() const;
  const FramePathCounters& counters() const { return counters_; }
  std::int64_t images_published() const {
    return images_published_.load(std::memory_order_relaxed);
  }
  // The command thread's side of CommandApplier (command_applier.hpp).
  bool submit_command(const Command& command) { return commands_.submit(command); }
  bool submit_detector(const Command& command, std::unique_ptr<pipeline::Detector> detector) {
    return commands_.submit_detector(command, std::move(detector));
  }
  bool take_command_result(Command* command) { return commands_.take_result(command); }
  // A message on the command channel that is not a command (status_t.bad_messages).
  void count_bad_command() { counters_.bad_commands.fetch_add(1, std::memory_order_relaxed); }
  static constexpr std::size_t kCommandSlots = CommandApplier::kSlots;

  // The threads sharing each frame's detection (pipeline.worker_threads): a replacement detector
  // is given them (Detector::use_parts()) before its reset().
  pipeline::PartRunner& detection_parts() { return parts_; }

  // The frames' nominal rate after start(): the camera's own (the memory camera's rate_hz) or
  // camera.frame_rate_hz. The per-frame budget and the latency windows follow it.
  double frame_rate_hz() const { return frame_rate_hz_; }
  // True once the camera ended by itself (a replayed recording reached its end).
  bool source_ended() const { return source_ended_.load(std::memory_order_acquire); }
  // The strobe's health in one line into `out` (no allocation): "" without laser.strobe_line,
  // "ok", or why frames fall back to the estimate. `matched`/`unmatched`: frames of the period
  // looked at. Any thread.
  void describe_strobe(std::int64_t now_mono, std::int64_t matched, std::int64_t unmatched,
                       char* out, std::size_t size) const;

 private:
  void camera_loop();
  void worker_loop();
  void publisher_loop();
  void image_loop();
  bool desired_laser(LaserMode mode, std::uint64_t grab_index) const;
  // `record` receives the switch's time and frame (camera thread only; others pass nullptr).
  void switch_laser(bool on, std::uint64_t for_frame, hal::LaserSwitch* record = nullptr);
  void fill_status(std::int64_t now_mono, std::int64_t period_ns);

  const DaemonConfig& config_;
  hal::Camera& camera_;
  hal::Laser& laser_;
  hal::ExposureStrobe* strobe_;   // the laser's strobe line, nullptr without one
  pipeline::Detector* detector_;  // the worker's; replaced by a threshold command
  lcm::LCM& lcm_;
  std::unique_ptr<lcm::LCM> image_lcm_;  // raw frames over UDP: their own socket and lock
  hal::FrameFormat format_;
  double frame_rate_hz_ = 0;

  std::unique_ptr<SpscRing<FrameSlot>> frames_;
  std::unique_ptr<SpscRing<ProfileSlot>> profiles_;
  pipeline::Profile unpublished_profile_;  // detector output when the profile ring is full
  std::unique_ptr<SpscRing<ImageSlot>> images_;
  std::unique_ptr<LcmPublisher> publisher_;
  std::unique_ptr<RawFrameEncoder> encoder_;
  std::unique_ptr<LatencyStats> latency_;   // exposure -> published
  std::unique_ptr<LatencyStats> pipeline_;  // arrival -> published

  FramePathCounters counters_;
  CommandApplier commands_;
  std::atomic<std::int64_t> profiles_published_{0};
  std::atomic<std::int64_t> images_published_{0};
  std::atomic<std::int64_t> publish_errors_{0};
  std::atomic<bool> running_{false};
  std::atomic<bool> stopping_{false};
  std::atomic<bool> worker_done_{false};
  std::atomic<bool> source_ended_{false};
  std::atomic<bool> images_done_{false};
  std::atomic<bool> stop_requested_{false};  // by stop(), unlike stopping_ (also end of source)
  std::int64_t start_mono_ns_ = 0;

  // Publisher-thread state for per-period figures.
  std::int64_t last_status_frames_ = 0;
  std::int64_t last_status_matched_ = 0;
  std::int64_t last_status_unmatched_ = 0;
  static constexpr std::size_t kStrobeLineBytes = 240;  // status_t.strobe_state at most
  std::int64_t points_in_period_ = 0;
  std::int64_t profiles_in_period_ = 0;
  CpuUsage cpu_;
  LatencySummary final_latency_;
  LatencySummary final_pipeline_;

  WorkerPool parts_;  // the worker and its helpers
  std::thread camera_thread_;
  std::thread worker_thread_;
  std::thread publisher_thread_;
  std::thread image_thread_;
};

}  // namespace laserline::daemon
