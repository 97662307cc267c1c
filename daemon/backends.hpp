#pragma once

#include <memory>

#include "daemon/config.hpp"
#include "hal/camera.hpp"
#include "hal/laser.hpp"
#include "pipeline/detector.hpp"

namespace laserline::daemon {

// The parts a configuration names, created but not opened: creating them validates every
// backend option (throws hal::ConfigError) without touching hardware.
struct Backends {
  std::unique_ptr<hal::Laser> laser;  // declared first: destroyed last, after the camera
  std::unique_ptr<hal::Camera> camera;
  std::unique_ptr<pipeline::Detector> detector;
};

Backends create_backends(DaemonConfig& config);

}  // namespace laserline::daemon
