#pragma once

// The simulated scene's geometry per frame: the surface and the laser sheet in the camera frame,
// and where the sheet meets the surface along an image line (flat or relieved). Internal to the
// simulator (hal/sim/).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "hal/sim/sim_scene.hpp"

namespace laserline::hal::sim {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

// Rotations by angle a (radians) about the x, y and z axes.
Mat3 rot_x(double a);
Mat3 rot_y(double a);
Mat3 rot_z(double a);

// Everything render() and ground_truth() need about one frame, in the camera frame.
struct FrameGeometry {
  bool surface = false;   // the surface plane is in front of the camera
  Vec3 n = Vec3::Zero();  // surface: n . X = d_surface, n pointing away from the camera
  double d_surface = 0;
  Mat3 h = Mat3::Zero();  // pixel (u, v, 1) -> (S, T, W); texel coordinates are S/W, T/W
  Eigen::Vector4d lp = Eigen::Vector4d::Zero();  // laser sheet a X + b Y + c Z + e = 0
  double fx = 1, fy = 1, cx = 0, cy = 0;
  // For the relief: surface coordinates (metres) of a camera-frame point X are
  // x = e1 . X + c1, y = e2 . X + c2, height toward the camera d_surface - n . X.
  Vec3 e1 = Vec3::Zero(), e2 = Vec3::Zero();
  double c1 = 0, c2 = 0;
  double texel_m = 1;
  double object_shift_m = 0;  // how far the relief (objects) moved along x (object_speed_m_s)
  // The laser's fan (SimSceneOptions::laser_fan_deg): a lit point X has
  // |fan_side . (X - fan_apex)| <= fan_tan_half * fan_axis . (X - fan_apex); none when 0.
  Vec3 fan_apex = Vec3::Zero(), fan_axis = Vec3::Zero(), fan_side = Vec3::Zero();
  double fan_tan_half = 0;
};

// The geometry of a frame whose camera-to-world rotation is r and position t.
FrameGeometry make_geometry(const SimSceneOptions& o, const Mat3& r, const Vec3& t,
                            double object_shift_m);

// Where the sheet's centre meets the surface along one image line.
struct LineHit {
  bool hit = false;
  double position = 0;  // along the line (pixels)
  double z = 0;         // depth of the lit surface point
  double s = 0;         // texel coordinates of the lit surface point (on the relief: on the
  double t = 0;         // object, moved with it)
};

// Along line k of `lines`; `relief` the relief tile or null (flat), relief_max its highest point.
LineHit solve_line(const FrameGeometry& g, const SimLineFamily& lines, double k,
                   const float* relief, double relief_max);

// Albedo of the flat surface seen at pixel (u, v).
float albedo_at(const FrameGeometry& g, const float* tex, double u, double v);

// Gaussian sigma (pixels, across the line) of the line at depth z.
double line_sigma(const SimSceneOptions& o, const SimLineFamily& lines, double z);

}  // namespace laserline::hal::sim
