#pragma once

#include <memory>

#include "hal/calibration.hpp"
#include "hal/registry.hpp"
#include "hal/sim/sim_scene.hpp"

namespace laserline::hal {

class YamlMap;
class SimCamera;

// The simulator's options from a `sim:` mapping (also used by tests and tools to rebuild the exact
// scene a daemon ran).
SimSceneOptions read_sim_options(YamlMap& sim, const Calibration& calibration,
                                 double frame_rate_hz);

// The sim backends' factories (hal/registry.hpp): the camera renders the `camera.sim` scene, the
// laser has no options.
std::unique_ptr<Camera> create_sim_camera(const CameraRequest& request);
// The same camera as its own type, for the memory camera, which renders its frames ahead.
std::unique_ptr<SimCamera> make_sim_camera(const CameraRequest& request);
std::unique_ptr<Laser> create_sim_laser(YamlMap& options);

}  // namespace laserline::hal
