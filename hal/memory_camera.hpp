#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "hal/camera.hpp"
#include "hal/laser.hpp"
#include "hal/registry.hpp"

namespace laserline::hal {

class SimCamera;

struct MemoryCameraOptions {
  int frames = 16;  // frames held: rendered, or the first ones of the recording
  // Frames delivered per second, paced on CLOCK_MONOTONIC like a free-running sensor; 0 = as fast
  // as the frame path takes them (paced_by_consumer(): nothing dropped).
  double rate_hz = 30;
  // Frames a late caller still gets, as a driver's queue of buffers keeps them (v4l2 4, aravis
  // 16); older ones are lost. 1: a sensor without a queue.
  int buffers = 4;
  std::int64_t loops = 0;  // times the frames are delivered before the source ends; 0 = endless
  double duration_s = 0;   // seconds after open() the source ends; 0 = endless
};

// Frames held in memory, delivered at any rate, so that the frame path can be driven past any
// real camera (docs/performance.md, "The whole daemon at rate"). The frames are made in open():
//  - rendered by the simulator (a SimCamera's scene), each twice, with the laser on and off; a
//    delivered frame is the one matching `laser` at that moment, as the simulator's would be;
//  - or read from a recording (a camera that is paced_by_consumer(), e.g. the `lcm` backend on
//    a file:// log): its first `frames` frames, with the laser state each was recorded with.
// After open() a grab is a copy from memory: no allocation, no syscall but the pacing sleep.
// Frames are numbered in the order due, across loops. A caller late by up to `buffers` frames
// gets them at once, as from a driver's queue; frames older than that are lost as a free-running
// camera loses them (counted in health().skipped_frames, a gap in the numbers).
//
// Thread context: open()/format() from the setup thread; grab() from the camera thread; stop()
// and health() from any thread.
class MemoryCamera final : public Camera {
 public:
  // Frames rendered by `sim` (not opened: only its scene is used); `laser` chooses between lit
  // and unlit frames at each grab.
  MemoryCamera(const MemoryCameraOptions& options, std::unique_ptr<SimCamera> sim,
               const Laser* laser);
  // Frames loaded from `recording`, which must be paced_by_consumer().
  MemoryCamera(const MemoryCameraOptions& options, std::unique_ptr<Camera> recording);
  ~MemoryCamera() override;

  bool open(std::string* error) override;
  FrameFormat format() const override { return format_; }
  GrabStatus grab(std::span<std::uint8_t> dst, FrameInfo& info,
                  std::chrono::milliseconds timeout) override;
  void stop() override;
  bool paced_by_consumer() const override { return options_.rate_hz == 0; }
  double own_frame_rate_hz() const override { return options_.rate_hz; }
  CameraHealth health() const override;

  // Frames held after open() (fewer than options.frames when a recording has fewer).
  int frames() const { return static_cast<int>(info_.size()); }

 private:
  bool render(std::string* error);
  bool load(std::string* error);

  MemoryCameraOptions options_;
  std::unique_ptr<SimCamera> sim_;
  std::unique_ptr<Camera> recording_;
  const Laser* laser_ = nullptr;
  FrameFormat format_;
  // Frame i: lit_[i] (with the laser on, or as recorded) and, for rendered frames, unlit_[i].
  std::vector<std::vector<std::uint8_t>> lit_;
  std::vector<std::vector<std::uint8_t>> unlit_;
  std::vector<FrameInfo> info_;
  std::int64_t period_ns_ = 0;
  std::int64_t start_mono_ns_ = 0;
  std::uint64_t next_sequence_ = 0;
  std::uint64_t end_sequence_ = 0;  // loops: the first sequence not delivered; 0 = none
  std::atomic<std::int64_t> skipped_frames_{0};
  std::atomic<bool> stopped_{false};
};

// The `memory` backend's factory (hal/registry.hpp). Options under `camera.memory`: source
// (sim, or the name of a recording backend such as lcm, whose own section then says which
// recording), frames, rate_hz (default camera.frame_rate_hz), buffers, loops, duration_s.
std::unique_ptr<Camera> create_memory_camera(const CameraRequest& request);

}  // namespace laserline::hal
