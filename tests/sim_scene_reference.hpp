#pragma once
// What the simulated scene's tests share: a rendered frame, its ground truth, and the geometry of
// the scene computed from the options as hal/sim/sim_scene.hpp documents them (never by the
// simulator's own code).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "hal/sim/sim_scene.hpp"

namespace laserline::hal::sim_reference {

using Vec3 = std::array<double, 3>;

// A frame as render() writes it: `channels` interleaved samples a pixel (1 for mono and Bayer).
struct Image {
  int width = 0;
  int height = 0;
  int channels = 1;
  std::vector<std::uint8_t> data;
  int at(int u, int v, int c = 0) const {
    return data[(static_cast<std::size_t>(v) * width + u) * channels + c];
  }
};

inline Image render(SimScene& scene, std::uint64_t sequence, bool laser_on) {
  const FrameFormat f = scene.format();
  const auto pixels = static_cast<std::size_t>(f.width) * f.height;
  Image img{f.width, f.height, static_cast<int>(scene.raw_bytes() / pixels),
            std::vector<std::uint8_t>(scene.raw_bytes())};
  scene.render(sequence, laser_on, img.data);
  return img;
}

inline SimGroundTruth truth_of(const SimScene& scene, std::uint64_t sequence, bool laser_on) {
  SimGroundTruth truth;
  scene.ground_truth(sequence, laser_on, truth);
  return truth;
}

// Only the laser, noiseless, on a surface of albedo 1: the line is the exact Gaussian, rounded.
inline SimSceneOptions laser_only(SimSceneOptions o) {
  o.noise_sigma = 0;
  o.texture_contrast = 0;
  o.ambient = 0;
  o.backscatter = 0;
  o.laser_peak = 200;
  return o;
}

inline int finite_count(const std::vector<float>& v) {
  return static_cast<int>(
      std::count_if(v.begin(), v.end(), [](float x) { return std::isfinite(x); }));
}

inline double dot3(const Vec3& a, const Vec3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// The surface's frame in the world: the base plane through (0, 0, distance_m), axes the world's
// x and y turned by tilt_y then tilt_x, the normal toward the camera.
struct SurfaceFrame {
  Vec3 e1, e2, normal;
  Vec3 origin;
};

inline SurfaceFrame surface_frame(const SimSceneOptions& o) {
  const double ax = o.tilt_x_deg * std::numbers::pi / 180.0;
  const double ay = o.tilt_y_deg * std::numbers::pi / 180.0;
  const double rx[9] = {1, 0, 0, 0, std::cos(ax), -std::sin(ax), 0, std::sin(ax), std::cos(ax)};
  const double ry[9] = {std::cos(ay), 0, std::sin(ay), 0, 1, 0, -std::sin(ay), 0, std::cos(ay)};
  double b[9];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      b[i * 3 + j] = rx[i * 3] * ry[j] + rx[i * 3 + 1] * ry[3 + j] + rx[i * 3 + 2] * ry[6 + j];
  }
  return {{b[0], b[3], b[6]}, {b[1], b[4], b[7]}, {-b[2], -b[5], -b[8]}, {0, 0, o.distance_m}};
}

// A world point in the camera's frame, and back.
inline Vec3 to_camera(const SimCameraPose& pose, const Vec3& x) {
  Vec3 out{};
  for (int i = 0; i < 3; ++i)
    out[i] = dot3({pose.rotation(i, 0), pose.rotation(i, 1), pose.rotation(i, 2)}, x) +
             pose.translation[i];
  return out;
}

inline Vec3 to_world(const SimCameraPose& pose, const Vec3& x) {
  const Vec3 d{x[0] - pose.translation[0], x[1] - pose.translation[1], x[2] - pose.translation[2]};
  Vec3 out{};
  for (int i = 0; i < 3; ++i)
    out[i] = pose.rotation(0, i) * d[0] + pose.rotation(1, i) * d[1] + pose.rotation(2, i) * d[2];
  return out;
}

}  // namespace laserline::hal::sim_reference
