#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "hal/camera.hpp"
#include "hal/laser.hpp"
#include "hal/laser_channel.hpp"

namespace laserline::hal {

struct Calibration;
class YamlMap;

// Backends are chosen by name from the configuration through these two registries, as libcamera
// chooses its pipeline handlers. Each backend owns its options: its factory (declared beside the
// backend) reads and validates them from `options` and throws ConfigError for a bad one; it does
// not touch hardware, which happens in open(). The backends in hal/ are listed in registry.cpp
// (a static library drops files nothing refers to, so a backend cannot register itself from a
// static constructor there); backends outside hal/ register with register_*_backend().

struct CameraRequest {
  YamlMap* options = nullptr;  // the `camera:` section
  const Calibration* calibration = nullptr;
  const Laser* laser = nullptr;  // the laser the camera sees (the simulator renders it)
  // The laser's light in colour frames (`camera.channel`): backends whose frames can be colour
  // convert them to the mono8 frame with it; mono sources (the simulator, a replayed log) take
  // their frames as they are.
  LaserChannel channel;
};

using CameraFactory = std::function<std::unique_ptr<Camera>(const CameraRequest&)>;
// Reads the `laser:` section's backend options.
using LaserFactory = std::function<std::unique_ptr<Laser>(YamlMap& options)>;

// Adds a backend that lives outside hal/ to the same registry: the LCM log replay is chosen by
// name like any camera, but it needs LCM, which hal/ must not know (it registers from daemon/).
// Call from the setup thread before make_camera(); a second call for a name is ignored.
void register_camera_backend(const std::string& name, CameraFactory create);
void register_laser_backend(const std::string& name, LaserFactory create);

std::vector<std::string> camera_backends();
std::vector<std::string> laser_backends();

// nullptr for a name no backend has.
std::unique_ptr<Camera> make_camera(const std::string& backend, const CameraRequest& request);
std::unique_ptr<Laser> make_laser(const std::string& backend, YamlMap& options);

}  // namespace laserline::hal
