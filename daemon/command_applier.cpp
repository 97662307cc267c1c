#include "daemon/command_applier.hpp"

#include <cstdio>
#include <span>
#include <utility>

namespace laserline::daemon {

bool CommandApplier::submit(const Command& command) {
  const bool worker =
      command.kind == CommandKind::kThreshold || command.kind == CommandKind::kRegion;
  SpscRing<Command>& ring = worker ? worker_commands_ : commands_;
  Command* slot = ring.try_claim();
  if (slot == nullptr) return false;
  *slot = command;
  ring.publish();
  return true;
}

bool CommandApplier::submit_detector(const Command& command,
                                     std::unique_ptr<pipeline::Detector> detector) {
  if (pending_detector_ != nullptr) return false;
  Command with = command;
  with.detector = detector.get();
  if (!submit(with)) return false;
  pending_detector_ = std::move(detector);
  return true;
}

bool CommandApplier::take_result(Command* command) {
  for (SpscRing<Command>* ring : {&command_results_, &worker_results_}) {
    Command* slot = ring->front();
    if (slot == nullptr) continue;
    *command = *slot;
    ring->pop();
    if (command->kind == CommandKind::kThreshold) {
      // The worker put the pending detector in place and no longer touches the one it replaced:
      // that one is freed here, unless it is the one the frame path was built with (its owner's).
      current_detector_ = std::move(pending_detector_);
      command->detector = nullptr;
    }
    return true;
  }
  return false;
}

void CommandApplier::run_worker_commands(pipeline::Detector*& detector) {
  while (Command* command = worker_commands_.front()) {
    Command* result = worker_results_.try_claim();
    if (result == nullptr) return;
    *result = *command;
    worker_commands_.pop();
    if (result->kind == CommandKind::kRegion) {
      // Checked against the frame by the command thread; only bounds change (no allocation).
      detector->set_region(result->region);
      result->region = detector->region();
    } else {
      // The replacement was built and sized (reset) for this frame size by the command thread.
      std::swap(detector, result->detector);
    }
    result->result.accepted = true;
    worker_results_.publish();
  }
}

void CommandApplier::run_camera_commands(LaserMode& mode, bool frames_flowing,
                                         std::uint64_t grab_index) {
  // A command stays queued until its result has room to go back.
  while (Command* command = commands_.front()) {
    Command* result = command_results_.try_claim();
    if (result == nullptr) return;
    *result = *command;
    commands_.pop();
    apply(*result, mode, frames_flowing, grab_index);
    command_results_.publish();
  }
}

void CommandApplier::apply(Command& command, LaserMode& mode, bool frames_flowing,
                           std::uint64_t grab_index) {
  hal::SettingResult& r = command.result;
  switch (command.kind) {
    case CommandKind::kCamera:
      camera_.apply_setting(command.setting, r);
      return;
    case CommandKind::kLaserMode:
      hal::write_setting_text(r.old_value, to_string(mode));
      if (command.laser_mode != LaserMode::kOff && (!frames_flowing || grab_index == 0)) {
        r.accepted = false;
        hal::write_setting_line(
            r.reason, "laser.mode: no frames are flowing (camera %s), the laser stays off",
            to_string(camera_state_.load(std::memory_order_relaxed)));
        return;
      }
      mode = command.laser_mode;
      hal::write_setting_text(r.in_force, to_string(mode));
      r.accepted = true;
      return;
    case CommandKind::kThreshold:  // the worker's (run_worker_commands)
    case CommandKind::kRegion:
      return;
    case CommandKind::kGet: {
      // "name=value" for every setting the camera has, then the laser's mode.
      std::span<char> rest(r.in_force);
      for (const char* name : {"exposure_us", "gain_db", "frame_rate_hz"}) {
        char value[hal::CameraSetting::kTextBytes];
        if (!camera_.read_setting(name, value)) continue;
        const int written = std::snprintf(rest.data(), rest.size(), "%s=%s ", name, value);
        if (written < 0 || static_cast<std::size_t>(written) >= rest.size()) break;
        rest = rest.subspan(static_cast<std::size_t>(written));
      }
      hal::write_setting_line(rest, "laser.mode=%s", to_string(mode));
      r.accepted = true;
      return;
    }
  }
}

}  // namespace laserline::daemon
