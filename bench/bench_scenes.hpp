#pragma once

#include "hal/sim/sim_scene.hpp"

// The simulated scanner the benchmarks render: the product's default mount on a camera of the
// given size (focal length scaled from 1400 px at 1280 wide), the wall tilted 8 degrees.
inline laserline::hal::SimSceneOptions sim_options(int width, int height) {
  laserline::hal::SimSceneOptions o;
  o.calibration.camera.width = width;
  o.calibration.camera.height = height;
  o.calibration.camera.fx = o.calibration.camera.fy = 1400.0 * width / 1280.0;
  o.calibration.camera.cx = (width - 1) / 2.0;
  o.calibration.camera.cy = (height - 1) / 2.0;
  o.tilt_y_deg = 8;
  return o;
}
