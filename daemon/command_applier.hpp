#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "daemon/command.hpp"
#include "daemon/config.hpp"
#include "daemon/frame_slots.hpp"
#include "daemon/spsc_ring.hpp"
#include "hal/camera.hpp"
#include "pipeline/detector.hpp"

namespace laserline::daemon {

// Carries parsed commands from the command thread to the thread that owns what they change, and
// their results back, through lock-free rings: the camera thread carries out camera settings, the
// laser's mode and get between two grabs; the worker puts a replacement detector (kThreshold) in
// place, or sets the detector's region (kRegion), between two frames. Neither of those threads
// allocates or locks here.
//
// Thread context: submit(), submit_detector() and take_result() from one command thread;
// run_camera_commands() from the camera thread; run_worker_commands() from the worker.
class CommandApplier {
 public:
  static constexpr std::size_t kSlots = 8;

  // `camera_state`: the camera thread's, named when a laser mode is refused.
  CommandApplier(hal::Camera& camera, const std::atomic<CameraState>& camera_state)
      : camera_(camera), camera_state_(camera_state) {}
  CommandApplier(const CommandApplier&) = delete;
  CommandApplier& operator=(const CommandApplier&) = delete;

  // Queues a command for the thread that carries it out (the worker for kThreshold and kRegion,
  // else the camera thread); false when kSlots are waiting already.
  bool submit(const Command& command);
  // kThreshold: `detector` (built with the new threshold and reset() to the camera's frame size)
  // replaces the worker's between two frames; owned here from now on. False while another
  // replacement is under way.
  bool submit_detector(const Command& command, std::unique_ptr<pipeline::Detector> detector);
  // The next command carried out, with its result; false when none is back yet. A detector
  // replaced by a threshold command is freed here, on the command thread.
  bool take_result(Command* command);

  // Camera thread, between two grabs: carries out the commands waiting. `mode` is the laser's,
  // changed from the next frame; a mode that switches the laser on is refused while frames do not
  // flow (before the first frame, after a timeout or an error).
  void run_camera_commands(LaserMode& mode, bool frames_flowing, std::uint64_t grab_index);
  // Worker, between two frames: puts replacement detectors in place of `detector`, sets its region.
  void run_worker_commands(pipeline::Detector*& detector);

 private:
  void apply(Command& command, LaserMode& mode, bool frames_flowing, std::uint64_t grab_index);

  hal::Camera& camera_;
  const std::atomic<CameraState>& camera_state_;
  SpscRing<Command> commands_{kSlots, Command{}};         // command thread -> camera thread
  SpscRing<Command> command_results_{kSlots, Command{}};  // and back
  SpscRing<Command> worker_commands_{kSlots, Command{}};  // command thread -> worker
  SpscRing<Command> worker_results_{kSlots, Command{}};   // and back
  // Command-thread state: the detector submitted and not yet answered, and the replacement in
  // force (null while the original is).
  std::unique_ptr<pipeline::Detector> pending_detector_;
  std::unique_ptr<pipeline::Detector> current_detector_;
};

}  // namespace laserline::daemon
