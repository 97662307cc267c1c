#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "hal/frame.hpp"
#include "pipeline/profile.hpp"

namespace laserline::daemon {

// A grabbed frame, camera thread -> worker.
struct FrameSlot {
  hal::FrameInfo info;
  std::vector<std::uint8_t> pixels;  // sized for the camera's format at start
};

// A processed frame's points, worker -> publisher.
struct ProfileSlot {
  hal::FrameInfo info;
  int width = 0;
  int height = 0;
  pipeline::Profile profile;
};

// A raw frame to publish, worker -> publisher (every n-th frame).
struct ImageSlot {
  hal::FrameInfo info;
  hal::FrameFormat format;
  std::vector<std::uint8_t> pixels;
};

enum class CameraState : std::uint8_t { kStarting, kStreaming, kTimeout, kError, kStopped };
const char* to_string(CameraState state);

// Counters written by the camera and worker threads and read by the publisher for status: each
// is a relaxed atomic because each is only a count, not a hand-over of data.
struct FramePathCounters {
  std::atomic<std::int64_t> frames_captured{0};
  std::atomic<std::int64_t> frames_processed{0};
  std::atomic<std::int64_t> frames_dropped{0};
  std::atomic<std::int64_t> profiles_dropped{0};
  std::atomic<std::int64_t> images_dropped{0};
  std::atomic<std::int64_t> grab_timeouts{0};
  std::atomic<std::int64_t> grab_errors{0};
  std::atomic<std::int64_t> laser_switches{0};
  std::atomic<std::int64_t> laser_errors{0};
  std::atomic<std::int64_t> laser_safety_offs{0};
  std::atomic<std::int64_t> frames_over_budget{0};  // detection longer than one frame period
  std::atomic<std::int64_t> processing_max_ns{0};   // longest detection since the last status
  std::atomic<std::int64_t> laser_late_switches{0};
  // laser.strobe_line: frames matched to an exposure on the strobe, and frames that were not
  // (their laser state is the estimate from the camera's timestamp).
  std::atomic<std::int64_t> strobe_matched{0};
  std::atomic<std::int64_t> strobe_unmatched{0};
  std::atomic<std::int64_t> last_frame_mono_ns{0};
  std::atomic<std::int64_t> bad_commands{0};  // command channel: not a valid command_t
  std::atomic<CameraState> camera_state{CameraState::kStarting};
};

}  // namespace laserline::daemon
