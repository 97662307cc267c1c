#pragma once

// What the simulated scene's renderer (sim_render.cpp) and its constructor (sim_scene.cpp, which
// sizes the scratch rows) share. Internal to the simulator (hal/sim/).

#include <array>
#include <limits>

#include "hal/sim/sim_lines.hpp"
#include "hal/sim/sim_scene.hpp"

namespace laserline::hal {

namespace sim {

// The row kernels work in blocks of kBlock pixels with a constant trip count and restrict
// pointers: that is what GCC's -O2 cost model needs to vectorise them. Scratch rows are padded
// to whole blocks.
inline constexpr int kBlock = 16;
inline constexpr float kNoGlow = 1e30f;  // inverse depth floor of the glow in lines without a line
inline constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

}  // namespace sim

struct SimScene::Pose {
  sim::Mat3 r = sim::Mat3::Identity();  // camera to world: X_world = r X_cam + t
  sim::Vec3 t = sim::Vec3::Zero();
};

}  // namespace laserline::hal
