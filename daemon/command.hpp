#pragma once

#include <laserline/command_t.hpp>

#include <cstdint>
#include <string>

#include "daemon/config.hpp"
#include "hal/camera.hpp"
#include "pipeline/detector.hpp"

namespace laserline::daemon {

// What a command changes, and so which thread carries it out: the camera thread owns the camera
// and the laser's switching, the worker the detector.
enum class CommandKind : std::uint8_t {
  kCamera,     // exposure_us, gain_db, frame_rate_hz, genicam:<Feature>, v4l2:<control>
  kLaserMode,  // laser.mode
  kThreshold,  // detector.maxvalue.threshold, detector.frontend.snr_threshold_db
  kGet,        // every value in force
  kRegion,     // detector.roi: the worker sets it on its detector
};

// One command on its way to the thread that carries it out and back with its result. Fixed
// buffers only: that thread takes it from a ring and fills it in place without allocating.
struct Command {
  std::int64_t id = 0;
  char sender[hal::CameraSetting::kTextBytes] = {};  // printable, for the log
  CommandKind kind = CommandKind::kGet;
  hal::CameraSetting setting;  // name and value as given (every kind); number where one is
  LaserMode laser_mode = LaserMode::kOff;
  // kThreshold: the detector with the new threshold, built and sized by the command thread; the
  // worker puts it in place and hands back the one it replaced here.
  pipeline::Detector* detector = nullptr;
  // kRegion: the region to search (whole(): the whole frame); back from the worker, the region
  // its detector searches now.
  pipeline::DetectionRegion region;
  hal::SettingResult result;
};

// Turns a decoded command_t into a Command, on the thread that received it: false with the one
// line why it is refused in *reason (the setting named) when the token is not the configured
// lcm.command_token, the name is none of the settings, or the value is not one the setting
// takes. Camera settings are checked by `camera` against the ranges its configuration takes
// (Camera::check_setting); laser.mode "pattern" needs the configuration's laser.pattern; a
// threshold must be the configured detector's and is checked by the pipeline's own validation,
// *options being `detector_options` (those in force) with it changed; detector.roi is
// "x,y,width,height" inside the camera's frame, or "full" (or empty) for the whole frame.
bool parse_command(const laserline::command_t& message, const DaemonConfig& config,
                   const hal::Camera& camera, const pipeline::DetectorOptions& detector_options,
                   Command* out, pipeline::DetectorOptions* options, std::string* reason);

// The threshold setting of a detector ("detector.maxvalue.threshold" or
// "detector.frontend.snr_threshold_db") and its value in `options`, as text.
const char* threshold_name(const std::string& detector);
std::string threshold_value(const std::string& detector, const pipeline::DetectorOptions& options);

// The command's texts as one printable line for the log: control characters become '?'.
std::string printable(const std::string& text);

}  // namespace laserline::daemon
