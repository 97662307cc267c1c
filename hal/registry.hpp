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
// not touch hardware, which happens in open().
//
// Each backend registers itself at the end of its own .cpp with a registration object of static
// storage duration (libcamera's REGISTER_PIPELINE_HANDLER):
//
//   const CameraBackendRegistration kAravis{"aravis", create_aravis_camera};
//
// so the registry knows no backend. Nothing refers to those objects, and a linker drops the
// members of a static library nothing refers to: the libraries that hold backends (laserline_hal,
// daemon/'s replay camera) are linked whole (WHOLE_ARCHIVE, see hal/CMakeLists.txt).

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

// Constructed before main(), on one thread; the registry is only read after. A second backend under
// a name already taken is a programming error: it aborts, naming the backend.
struct CameraBackendRegistration {
  CameraBackendRegistration(const char* name, CameraFactory create);
};
struct LaserBackendRegistration {
  LaserBackendRegistration(const char* name, LaserFactory create);
};

// The names registered, sorted.
std::vector<std::string> camera_backends();
std::vector<std::string> laser_backends();

// nullptr for a name no backend has.
std::unique_ptr<Camera> make_camera(const std::string& backend, const CameraRequest& request);
std::unique_ptr<Laser> make_laser(const std::string& backend, YamlMap& options);

}  // namespace laserline::hal
