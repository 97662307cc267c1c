#pragma once

#include <laserline/command_t.hpp>

#include <cstdint>
#include <string>

#include "daemon/config.hpp"
#include "hal/camera.hpp"

namespace laserline::daemon {

// What a command changes, and so which thread carries it out: the camera thread owns the camera
// and the laser's switching.
enum class CommandKind : std::uint8_t {
  kCamera,     // exposure_us, gain_db, frame_rate_hz, genicam:<Feature>, v4l2:<control>
  kLaserMode,  // laser.mode
  kGet,        // every value in force
};

// One command on its way to the thread that carries it out and back with its result. Fixed
// buffers only: that thread takes it from a ring and fills it in place without allocating.
struct Command {
  std::int64_t id = 0;
  char sender[hal::CameraSetting::kTextBytes] = {};  // printable, for the log
  CommandKind kind = CommandKind::kGet;
  hal::CameraSetting setting;  // name and value as given (every kind); number where one is
  LaserMode laser_mode = LaserMode::kOff;
  hal::SettingResult result;
};

// Turns a decoded command_t into a Command, on the thread that received it: false with the one
// line why it is refused in *reason (the setting named) when the token is not the configured
// lcm.command_token, the name is none of the settings, or the value is not one the setting
// takes. Camera settings are checked by `camera` against the ranges its configuration takes
// (Camera::check_setting); laser.mode "pattern" needs the configuration's laser.pattern.
bool parse_command(const laserline::command_t& message, const DaemonConfig& config,
                   const hal::Camera& camera, Command* out, std::string* reason);

// The command's texts as one printable line for the log: control characters become '?'.
std::string printable(const std::string& text);

}  // namespace laserline::daemon
