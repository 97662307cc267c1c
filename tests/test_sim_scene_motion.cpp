// The simulator's motion: objects sliding over the still base plane, and the camera panning.
// Each checks the renderer against a computation made here or in sim_scene_reference.hpp from the
// options as sim_scene.hpp documents them, never against the renderer's own intermediate numbers.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hal/sim/sim_scene.hpp"
#include "sim_scene_reference.hpp"

namespace laserline::hal {
namespace {

using namespace sim_reference;

// ---- Moving objects ----------------------------------------------------------------------------

// Where the ray of pixel (u, v) first meets the relieved surface whose relief has moved by
// `shift` metres along the surface's x axis (height at (x, y): relief_height(x - shift, y)), by
// brute force: marched in 1 mm steps through the slab the relief can occupy, then bisected.
// Returns the world point.
Vec3 ray_hit(const SimScene& scene, const SimCameraPose& pose, double u, double v, double shift) {
  const SimSceneOptions& o = scene.options();
  const SurfaceFrame f = surface_frame(o);
  const Vec3 ray = ray_of(o.calibration.camera, u, v);
  auto point = [&](double z) { return to_world(pose, {z * ray[0], z * ray[1], z}); };
  auto above = [&](double z) {
    const Vec3 l = surface_coordinates(f, point(z));
    return l[2] - scene.relief_height(l[0] - shift, l[1]);
  };
  // Height above the base plane is affine in z.
  const double h0 = surface_coordinates(f, point(0.0))[2];
  const double h1 = surface_coordinates(f, point(1.0))[2];
  double lo = (h0 - (o.relief_height_m + 0.01)) / (h0 - h1), hi = (h0 + 0.01) / (h0 - h1);
  return point(first_zero(above, lo, hi, 0.001 / std::sqrt(dot3(ray, ray))));
}

// A pier's piles and bumps sliding past a still camera.
SimSceneOptions moving_relief_options() {
  SimSceneOptions o = still_options();
  o.tilt_y_deg = 8;
  o.relief_height_m = 0.30;
  o.relief_min_height_m = 0.05;
  o.relief_per_m2 = 1.0;
  o.relief_max_slope = 0.9;
  o.object_speed_m_s = 0.5;
  o.seed = 2;
  return o;
}

TEST(SimSceneObjects, TheBasePlaneStaysWhileTheReliefAndItsTextureSlideAlongX) {
  SimSceneOptions o = moving_relief_options();
  o.noise_sigma = 0;
  o.ambient = 150;
  o.texture_contrast = 0.6;
  SimScene scene(o);
  const std::uint64_t a = 6, b = 21;  // 0.5 s apart: the objects move 25 cm
  const double shift_a = o.object_speed_m_s * a / o.frame_rate_hz;
  const double shift_b = o.object_speed_m_s * b / o.frame_rate_hz;
  const Image ia = render(scene, a, false), ib = render(scene, b, false);
  const SimCameraPose pose = scene.camera_pose(a);
  for (const std::uint64_t seq : {b, std::uint64_t{0}}) {
    const SimCameraPose other = scene.camera_pose(seq);
    EXPECT_EQ(other.rotation, pose.rotation);  // the camera holds still
    EXPECT_EQ(other.translation, pose.translation);
  }
  const SurfaceFrame f = surface_frame(o);
  const CameraIntrinsics& cam = o.calibration.camera;

  // Pixels whose ray meets the base plane where no relief is, nor within 1 cm, at either time
  // (the slope limit lets nothing hide such a point): the same grey, bit for bit.
  const CameraPlane plane = base_plane_in_camera(o, pose);
  int bare = 0, on_objects = 0, changed_on_objects = 0;
  for (int v = 0; v < ia.height; ++v) {
    for (int u = 0; u < ia.width; ++u) {
      const Vec3 r = ray_of(cam, u, v);
      const double z = plane.d / dot3(plane.n, r);
      const Vec3 s = surface_coordinates(f, to_world(pose, {z * r[0], z * r[1], z}));
      double highest = 0;
      for (double shift : {shift_a, shift_b}) {
        for (double dy : {-0.01, 0.0, 0.01}) {
          for (double dx : {-0.01, 0.0, 0.01})
            highest = std::max(highest, scene.relief_height(s[0] + dx - shift, s[1] + dy));
        }
      }
      if (highest == 0) {
        ASSERT_EQ(ia.at(u, v), ib.at(u, v)) << "bare plane at " << u << ", " << v;
        ++bare;
      } else if (highest > 0.05) {
        ++on_objects;
        changed_on_objects += ia.at(u, v) != ib.at(u, v) ? 1 : 0;
      }
    }
  }
  std::printf("  %d pixels on the bare plane unchanged; %d of %d on objects changed\n", bare,
              changed_on_objects, on_objects);
  EXPECT_GT(bare, ia.width * ia.height / 10);
  EXPECT_GT(changed_on_objects, on_objects / 2);

  // A point of an object seen in frame a is found again in frame b where it moved to (speed *
  // time along the surface's x axis), not where it was.
  auto sample = [&](double x, double y) {
    const int u0 = static_cast<int>(x), v0 = static_cast<int>(y);
    const double fu = x - u0, fv = y - v0;
    return (1 - fv) * ((1 - fu) * ib.at(u0, v0) + fu * ib.at(u0 + 1, v0)) +
           fv * ((1 - fu) * ib.at(u0, v0 + 1) + fu * ib.at(u0 + 1, v0 + 1));
  };
  double error_moved = 0, error_still = 0, travel = 0;
  int used = 0;
  for (int v = 8; v < ia.height - 8; v += 5) {
    for (int u = 8; u < ia.width - 8; u += 5) {
      const Vec3 hit = ray_hit(scene, pose, u, v, shift_a);
      const Vec3 local = surface_coordinates(f, hit);
      if (!(local[2] > 0.05)) continue;  // on an object only
      const double d = shift_b - shift_a;
      const Vec3 moved =
          to_camera(pose, {hit[0] + d * f.e1[0], hit[1] + d * f.e1[1], hit[2] + d * f.e1[2]});
      const double x = cam.cx + cam.fx * moved[0] / moved[2];
      const double y = cam.cy + cam.fy * moved[1] / moved[2];
      if (x < 1 || y < 1 || x > ib.width - 2 || y > ib.height - 2) continue;
      error_moved += std::abs(ia.at(u, v) - sample(x, y));
      error_still += std::abs(ia.at(u, v) - ib.at(u, v));
      travel += std::hypot(x - u, y - v);
      ++used;
    }
  }
  ASSERT_GT(used, 200);
  std::printf(
      "  %d points on objects moved %.1f px: grey error %.2f where they moved to, %.2f where they "
      "were\n",
      used, travel / used, error_moved / used, error_still / used);
  EXPECT_LT(error_moved / used, 4.0);  // bilinear sampling of frame b across hard texture edges
  EXPECT_LT(error_moved, 0.3 * error_still);
}

TEST(SimSceneObjects, TruthOnTheMovingReliefMatchesABruteForceSearchAlongTheCameraRays) {
  // As test_sim_scene.cpp's relief test, with the relief moved: every pixel's ray is marched to
  // the surface whose relief is shifted by speed * time, and the laser is where the hit crosses
  // the sheet.
  const SimSceneOptions o = moving_relief_options();
  SimScene scene(o);
  const std::uint64_t seq = 40;
  const double shift = o.object_speed_m_s * seq / o.frame_rate_hz;
  const SimGroundTruth truth = truth_of(scene, seq, true);
  const SimGroundTruth at_start = truth_of(scene, 0, true);
  const SimCameraPose pose = scene.camera_pose(seq);
  const auto sheet = o.calibration.laser.plane_coefficients();
  auto sheet_side = [&](int u, double v) {
    const Vec3 x = to_camera(pose, ray_hit(scene, pose, u, v, shift));
    return sheet[0] * x[0] + sheet[1] * x[1] + sheet[2] * x[2] + sheet[3];
  };
  const SurfaceFrame f = surface_frame(o);
  int checked = 0, on_relief = 0, moved = 0;
  double worst_row = 0, worst_depth = 0;
  for (int u = 0; u < o.calibration.camera.width; u += 4) {
    if (!std::isfinite(truth.position[u])) continue;
    int crossings = 0;
    const double row = sheet_crossing_row(sheet_side, u, o.calibration.camera.height, crossings);
    ASSERT_EQ(crossings, 1) << "column " << u << ": the line must be seen once";
    const Vec3 world = ray_hit(scene, pose, u, row, shift);
    const double depth = to_camera(pose, world)[2];
    EXPECT_NEAR(truth.position[u], row, 1e-3) << "column " << u;
    EXPECT_NEAR(truth.depth_m[u], depth, 1e-5) << "column " << u;
    worst_row = std::max(worst_row, std::abs(truth.position[u] - row));
    worst_depth = std::max(worst_depth, std::abs(truth.depth_m[u] - depth));
    on_relief += surface_coordinates(f, world)[2] > 0.05 ? 1 : 0;
    moved += std::abs(truth.position[u] - at_start.position[u]) > 0.5 ? 1 : 0;
    ++checked;
  }
  std::printf(
      "  %d columns, %d on relief above 5 cm, %d moved since frame 0: worst row %.2e px, depth "
      "%.2e m\n",
      checked, on_relief, moved, worst_row, worst_depth);
  EXPECT_GT(checked, 70);
  EXPECT_GT(on_relief, checked / 5);
  EXPECT_GT(moved, checked / 5);

  // And the rendered line is where the truth says (noiseless, laser only).
  SimScene lit(laser_only(o));
  const Image img = render(lit, seq, true);
  const SimGroundTruth t2 = truth_of(lit, seq, true);
  int used = 0;
  for (int u = 0; u < img.width; ++u) {
    if (!std::isfinite(t2.position[u])) continue;
    double bound = 0;
    const double fit = fit_axis_line(img, t2.lines, u, bound);
    EXPECT_NEAR(fit, t2.position[u], 0.03) << "column " << u;
    ++used;
  }
  EXPECT_GT(used, 300);
}

// ---- Panning ---------------------------------------------------------------------------------

// The scan's angle at time t: a triangle wave from 0 up to +amplitude, down to -amplitude and
// back to 0, at rate degrees a second.
double scan_angle_deg(double rate, double amplitude, double t) {
  const double x = std::fmod(rate * t, 4 * amplitude);
  if (x <= amplitude) return x;
  if (x <= 3 * amplitude) return 2 * amplitude - x;
  return x - 4 * amplitude;
}

TEST(SimScenePan, TheCameraTurnsAboutItsYAxisByTheScansTriangleWave) {
  SimSceneOptions o = still_options();
  o.scan_rate_deg_s = 12;
  o.scan_amplitude_deg = 6;  // a period of 2 s, 60 frames
  for (const bool pan : {false, true}) {
    SCOPED_TRACE(pan ? "pan" : "tilt");
    o.scan_pan = pan;
    SimScene scene(o);
    double sign = 0, largest = 0;
    for (std::uint64_t seq = 0; seq <= 130; ++seq) {
      const double expected = scan_angle_deg(12, 6, seq / o.frame_rate_hz) * kDegree;
      const SimCameraPose pose = scene.camera_pose(seq);
      const auto& r = pose.rotation;  // world -> camera; its last row is the optical axis
      for (double t : pose.translation)
        EXPECT_NEAR(t, 0.0, 1e-15);
      if (pan) {
        // The y axis stays; the optical axis turns in the x-z plane.
        EXPECT_NEAR(r(1, 1), 1.0, 1e-12);
        EXPECT_NEAR(r(0, 1), 0.0, 1e-12);
        EXPECT_NEAR(r(2, 1), 0.0, 1e-12);
        const double angle = std::atan2(r(2, 0), r(2, 2));
        if (sign == 0 && std::abs(angle) > 1e-3) sign = angle > 0 ? 1 : -1;
        EXPECT_NEAR(angle, sign * expected, 1e-12) << "frame " << seq;
        largest = std::max(largest, std::abs(angle));
      } else {
        // The x axis stays; the optical axis turns up (toward -y) first.
        EXPECT_NEAR(r(0, 0), 1.0, 1e-12);
        EXPECT_NEAR(r(1, 0), 0.0, 1e-12);
        EXPECT_NEAR(r(2, 0), 0.0, 1e-12);
        EXPECT_NEAR(std::atan2(-r(2, 1), r(2, 2)), expected, 1e-12) << "frame " << seq;
        largest = std::max(largest, std::abs(std::atan2(-r(2, 1), r(2, 2))));
      }
    }
    EXPECT_NEAR(largest, 6 * kDegree, 1e-12);
  }

  // With the laser beside the camera the scene moves across the line, which runs down the image:
  // the texture of frame a is found in frame b where the poses put the surface's points (a
  // horizontal shift of some 7 px), and the truth along rows is exact in the turned camera.
  o.scan_pan = true;
  o.calibration.laser.side = LaserSide::kLeft;
  o.noise_sigma = 0;
  o.ambient = 150;
  o.texture_contrast = 0.6;
  SimScene scene(o);
  const std::uint64_t a = 3, b = 6;
  const Image ia = render(scene, a, false), ib = render(scene, b, false);
  const SimCameraPose pa = scene.camera_pose(a), pb = scene.camera_pose(b);
  const CameraPlane plane = base_plane_in_camera(o, pa);
  const CameraIntrinsics& cam = o.calibration.camera;
  auto sample = [&](double x, double y) {
    const int u0 = static_cast<int>(x), v0 = static_cast<int>(y);
    const double fu = x - u0, fv = y - v0;
    return (1 - fv) * ((1 - fu) * ib.at(u0, v0) + fu * ib.at(u0 + 1, v0)) +
           fv * ((1 - fu) * ib.at(u0, v0 + 1) + fu * ib.at(u0 + 1, v0 + 1));
  };
  double error_posed = 0, error_still = 0, shift_u = 0, shift_v = 0;
  int used = 0;
  for (int v = 4; v < ia.height - 4; v += 3) {
    for (int u = 4; u < ia.width - 4; u += 3) {
      const Vec3 r = ray_of(cam, u, v);
      const double z = plane.d / dot3(plane.n, r);
      const Vec3 x = to_camera(pb, to_world(pa, {z * r[0], z * r[1], z}));
      const double ub = cam.cx + cam.fx * x[0] / x[2], vb = cam.cy + cam.fy * x[1] / x[2];
      if (ub < 1 || vb < 1 || ub > ib.width - 2 || vb > ib.height - 2) continue;
      error_posed += std::abs(ia.at(u, v) - sample(ub, vb));
      error_still += std::abs(ia.at(u, v) - ib.at(u, v));
      shift_u += std::abs(ub - u);
      shift_v += std::abs(vb - v);
      ++used;
    }
  }
  ASSERT_GT(used, 5000);
  std::printf("  pan: shift %.2f px across, %.2f px down; grey error %.2f posed, %.2f still\n",
              shift_u / used, shift_v / used, error_posed / used, error_still / used);
  EXPECT_GT(shift_u / used, 5.0);
  EXPECT_LT(shift_v / used, 0.1 * shift_u / used);
  EXPECT_LT(error_posed / used, 4.0);  // bilinear sampling of frame b across hard texture edges
  EXPECT_LT(error_posed, 0.3 * error_still);
  for (const std::uint64_t seq : {a, b, std::uint64_t{20}}) {
    const TruthCounts counts = expect_flat_truth_exact(scene, seq, truth_of(scene, seq, true));
    EXPECT_EQ(counts.lit, cam.height) << "frame " << seq;
  }
}

}  // namespace
}  // namespace laserline::hal
