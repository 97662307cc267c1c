#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/camera.hpp"
#include "hal/laser.hpp"
#include "hal/laser_channel.hpp"
#include "hal/sim/sim_scene.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {

// Backends are chosen by name from the configuration through these two factories (one table
// each, in registry.cpp). A factory reads and validates its backend's own options from `options`
// and throws ConfigError for a bad one; it does not touch hardware: that happens in open().

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

// Adds a camera backend that lives outside hal/ to the same table: the LCM log replay is chosen
// by name like any camera, but it needs LCM, which hal/ must not know (it registers from
// daemon/). Call from the setup thread before make_camera(); a second call for a name is ignored.
void register_camera_backend(const std::string& name, CameraFactory create);

std::vector<std::string> camera_backends();
std::vector<std::string> laser_backends();

std::unique_ptr<Camera> make_camera(const std::string& backend, const CameraRequest& request);
std::unique_ptr<Laser> make_laser(const std::string& backend, YamlMap& options);

// The simulator's options from a `sim:` mapping (also used by tests and tools to rebuild the exact
// scene a daemon ran).
SimSceneOptions read_sim_options(YamlMap& sim, const Calibration& calibration,
                                 double frame_rate_hz);

}  // namespace laserline::hal
