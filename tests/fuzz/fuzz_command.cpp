// libFuzzer: a message on laserlined's command channel, as the command thread takes it: the
// checked decode of laserline.command_t, then parse_command() against the built-in configuration
// (or one with a token and a laser pattern) and the simulated camera's ranges. Its contract: no
// crash or exception; a refusal always says why; an accepted command's texts are NUL-terminated
// in their fixed buffers, its number lies in the camera's range and its region in the frame.
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>

#include "daemon/command.hpp"
#include "hal/sim/sim_camera.hpp"
#include "tests/fuzz/fuzz_message.hpp"

namespace {

using laserline::daemon::Command;
using laserline::daemon::CommandKind;
using laserline::daemon::DaemonConfig;

struct Setup {
  DaemonConfig plain = laserline::daemon::builtin_config();
  DaemonConfig guarded = [] {
    DaemonConfig c = laserline::daemon::builtin_config();
    c.command_token = "s3cret";
    c.laser_pattern = {true, true, false};
    return c;
  }();
  laserline::hal::SimCamera camera = [this] {
    laserline::hal::SimSceneOptions options;
    options.calibration = plain.calibration;
    return laserline::hal::SimCamera(options, nullptr);
  }();
};

bool terminated(const char* text, std::size_t size) {
  return std::memchr(text, 0, size) != nullptr;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_message<laserline::command_t>(data, size);
  laserline::command_t message;
  std::string problem;
  if (!laserline::messages::decode(data, size, &message, {}, &problem)) return 0;
  static Setup setup;
  Command command;
  std::string reason;
  const DaemonConfig& config = (message.id & 1) != 0 ? setup.guarded : setup.plain;
  laserline::pipeline::DetectorOptions options;
  const bool accepted = laserline::daemon::parse_command(
      message, config, setup.camera, config.detector_options, &command, &options, &reason);
  if (!terminated(command.sender, sizeof command.sender) ||
      !terminated(command.setting.name, sizeof command.setting.name) ||
      !terminated(command.setting.value, sizeof command.setting.value)) {
    std::abort();
  }
  if (!accepted) {
    if (reason.empty()) std::abort();
    return 0;
  }
  if (command.id != message.id || message.name != command.setting.name) std::abort();
  if (command.kind == CommandKind::kThreshold) {
    options.validate();  // what was accepted is what the pipeline takes: this must not throw
  }
  if (command.kind == CommandKind::kRegion) {
    const laserline::hal::FrameFormat format = setup.camera.format();
    command.region.validate(format.width, format.height);  // inside the frame: must not throw
  }
  if (command.kind == CommandKind::kCamera) {
    const std::string name = command.setting.name;
    const double v = command.setting.number;
    if (name == "exposure_us" && !laserline::hal::kSimExposureRange.holds(v)) std::abort();
    if (name == "gain_db" && !laserline::hal::kSimGainRange.holds(v)) std::abort();
  }
  return 0;
}
