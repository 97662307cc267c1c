#pragma once
// What the simulated scene's tests share: a rendered frame, its ground truth, and the geometry of
// the scene computed from the options as hal/sim/sim_scene.hpp documents them (never by the
// simulator's own code). The features' tests (test_sim_scene_*.cpp) share the second part: the
// still scene, the sheet's geometry, exact truth on a flat surface and fits of the rendered lines.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <utility>
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

// The first zero of `above` between `lo` and `hi` (positive before it), marched in `step`s, then
// bisected.
template <typename Above>
double first_zero(const Above& above, double lo, double hi, double step) {
  for (double z = lo + step; z < hi + step; z += step) {
    if (above(std::min(z, hi)) <= 0) {
      hi = std::min(z, hi);
      break;
    }
    lo = z;
  }
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (above(mid) > 0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// The row at which column `u` sees the laser sheet, by brute force: `side(u, v)` is the signed
// distance to the sheet of what row v of the column sees; rows 0 .. height - 1 are marched for a
// change of sign, then the last change is bisected. `crossings`: how many changes there were.
template <typename Side>
double sheet_crossing_row(const Side& side, int u, int height, int& crossings) {
  crossings = 0;
  double lo = 0, hi = 0;
  double previous = side(u, 0);
  for (int v = 1; v < height; ++v) {
    const double here = side(u, v);
    if ((here > 0) != (previous > 0)) {
      ++crossings;
      lo = v - 1;
      hi = v;
    }
    previous = here;
  }
  const bool lo_positive = side(u, lo) > 0;
  for (int i = 0; i < 40; ++i) {
    const double mid = 0.5 * (lo + hi);
    ((side(u, mid) > 0) == lo_positive ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// ---- The features' tests ---------------------------------------------------------------

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kDegree = kPi / 180.0;

inline SimGroundTruth truth_along(const SimScene& scene, std::uint64_t sequence, bool laser_on,
                                  const SimLineFamily& lines) {
  SimGroundTruth truth;
  scene.ground_truth(sequence, laser_on, lines, truth);
  return truth;
}

// A small scene keeps the tests quick.
inline SimSceneOptions small_options() {
  SimSceneOptions o;
  o.calibration.camera.width = 320;
  o.calibration.camera.height = 256;
  o.calibration.camera.fx = o.calibration.camera.fy = 350;
  o.calibration.camera.cx = 159.5;
  o.calibration.camera.cy = 127.5;
  return o;
}

// ... with the camera holding still unless a test moves it.
inline SimSceneOptions still_options() {
  SimSceneOptions o = small_options();
  o.sway_m = 0;
  o.sway_deg = 0;
  return o;
}

// The paper's sheet (projector above the camera) turned by `angle` about the optical axis: its
// normal (0, 1, -tan(90 deg - beta)) rotated in the x-y plane.
inline Eigen::Vector4d turned_sheet(const LaserMount& mount, double angle) {
  const double t = std::tan(kPi / 2 - mount.angle_deg * kDegree);
  return Eigen::Vector4d{-std::sin(angle), std::cos(angle), -t, mount.baseline_m};
}

inline bool same_floats(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!(a[i] == b[i] || (std::isnan(a[i]) && std::isnan(b[i])))) return false;
  }
  return true;
}

inline bool same_truth(const SimGroundTruth& a, const SimGroundTruth& b) {
  return same_floats(a.position, b.position) && same_floats(a.depth_m, b.depth_m) &&
         same_floats(a.width_px, b.width_px);
}

// ---- Geometry, from the options as the header documents them -----------------------------

// The ray (X/Z, Y/Z, 1) of image point (x, y).
inline Vec3 ray_of(const CameraIntrinsics& cam, double x, double y) {
  return {(x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0};
}

// A world point in the surface's frame: along e1, along e2, height toward the camera.
inline Vec3 surface_coordinates(const SurfaceFrame& f, const Vec3& world) {
  const Vec3 d{world[0] - f.origin[0], world[1] - f.origin[1], world[2] - f.origin[2]};
  return {dot3(f.e1, d), dot3(f.e2, d), dot3(f.normal, d)};
}

// The base plane in the camera frame of one frame: n . X = d, n pointing away from the camera.
struct CameraPlane {
  Vec3 n;
  double d;
};

inline CameraPlane base_plane_in_camera(const SimSceneOptions& o, const SimCameraPose& pose) {
  const SurfaceFrame f = surface_frame(o);
  // World points X_w with normal . (X_w - origin) = 0, X_w = to_world(X_c): linear in X_c.
  const Vec3 at_camera = surface_coordinates(f, to_world(pose, {0, 0, 0}));
  Vec3 n{};
  for (int i = 0; i < 3; ++i) {
    Vec3 unit{};
    unit[i] = 1;
    n[i] = -(surface_coordinates(f, to_world(pose, unit))[2] - at_camera[2]);
  }
  return {n, at_camera[2]};
}

// The laser sheet's inverse depth 1/Z along the ray of image point (x, y) (<= 0: no crossing in
// front of the camera).
inline double sheet_inverse_depth(const Calibration& c, double x, double y) {
  const Eigen::Vector4d sheet = c.laser.plane_coefficients();
  const double a = sheet[0], b = sheet[1], cz = sheet[2], e = sheet[3];
  const Vec3 r = ray_of(c.camera, x, y);
  return -(a * r[0] + b * r[1] + cz * r[2]) / e;
}

// Where the sheet meets the flat base plane along line k of `lines`, in closed form: on the ray
// r(p) = r0 + p rd of the line's pixel at position p, the sheet is at Z = -e / (s . r) and the
// plane at Z = d / (n . r); equal where -e (n . r) = d (s . r), linear in p.
struct FlatHit {
  bool hit = false;
  double position = 0, depth = 0;
};

inline FlatHit flat_hit(const SimSceneOptions& o, const SimCameraPose& pose,
                        const SimLineFamily& lines, int k) {
  const CameraIntrinsics& cam = o.calibration.camera;
  const Eigen::Vector4d sheet = o.calibration.laser.plane_coefficients();
  const double a = sheet[0], b = sheet[1], c = sheet[2], e = sheet[3];
  const Vec3 s{a, b, c};
  const CameraPlane plane = base_plane_in_camera(o, pose);
  const auto [x0, y0] = lines.to_image(k, 0.0);
  const Vec3 r0 = ray_of(cam, x0, y0);
  const Vec3 rd{lines.along[0] / cam.fx, lines.along[1] / cam.fy, 0.0};
  const double k0 = e * dot3(plane.n, r0) + plane.d * dot3(s, r0);
  const double k1 = e * dot3(plane.n, rd) + plane.d * dot3(s, rd);
  FlatHit out;
  if (plane.d <= 0 || std::abs(k1) < 1e-12) return out;
  out.position = -k0 / k1;
  const Vec3 r{r0[0] + out.position * rd[0], r0[1] + out.position * rd[1], 1.0};
  out.depth = plane.d / dot3(plane.n, r);
  out.hit = out.depth > 0;
  return out;
}

// Whether image point (x, y) of line family `lines` lies `margin` px inside the frame along each
// image axis the lines cross (the axes `along` has a component on), and how near it is to that
// limit.
inline bool inside_frame(const CameraIntrinsics& cam, const SimLineFamily& lines, double x,
                         double y, double margin, double& slack) {
  slack = 1e300;
  bool inside = true;
  const double at[2] = {x, y};
  const double last[2] = {cam.width - 1.0, cam.height - 1.0};
  for (int axis = 0; axis < 2; ++axis) {
    if (lines.along[axis] == 0) {
      inside = inside && at[axis] >= 0 && at[axis] <= last[axis];  // on a line of the frame
      continue;
    }
    slack =
        std::min({slack, std::abs(at[axis] - margin), std::abs(last[axis] - margin - at[axis])});
    inside = inside && at[axis] >= margin && at[axis] <= last[axis] - margin;
  }
  return inside;
}

// Checks the truth of a flat-surface frame along `truth.lines` line by line: finite exactly where
// the sheet meets the surface 1.5 px inside the frame (along the axes the lines cross), there at
// the position and depth solved in closed form above, and its 3-D point on both the sheet and the
// surface. The truth's position and depth are floats: 1e-3 px and 1e-5 m are some 30 and 100 times
// their rounding. Returns how many lines are lit and how many of the others are hit just outside
// the 1.5 px margin (so that a caller can check that its scene tests the edge).
struct TruthCounts {
  int lit = 0;
  int at_edge = 0;
};

inline TruthCounts expect_flat_truth_exact(const SimScene& scene, std::uint64_t sequence,
                                           const SimGroundTruth& truth) {
  const SimSceneOptions& o = scene.options();
  const CameraIntrinsics& cam = o.calibration.camera;
  const SimCameraPose pose = scene.camera_pose(sequence);
  const CameraPlane plane = base_plane_in_camera(o, pose);
  const Eigen::Vector4d sheet = o.calibration.laser.plane_coefficients();
  const double a = sheet[0], b = sheet[1], c = sheet[2], e = sheet[3];
  const double sheet_norm = std::sqrt(a * a + b * b + c * c);
  TruthCounts counts;
  EXPECT_EQ(static_cast<int>(truth.position.size()), truth.lines.count);
  for (int k = 0; k < truth.lines.count; ++k) {
    const FlatHit hit = flat_hit(o, pose, truth.lines, k);
    const auto [x, y] = truth.lines.to_image(k, hit.position);
    double slack = 0;
    const bool inside = hit.hit && inside_frame(cam, truth.lines, x, y, 1.5, slack);
    if (hit.hit && slack < 1e-3) continue;  // on the margin itself: either answer is right
    if (!inside) {
      EXPECT_TRUE(std::isnan(truth.position[k])) << "line " << k << " at " << x << ", " << y;
      EXPECT_TRUE(std::isnan(truth.depth_m[k]) && std::isnan(truth.width_px[k]));
      if (hit.hit && x >= 0 && y >= 0 && x <= cam.width - 1 && y <= cam.height - 1)
        ++counts.at_edge;
      continue;
    }
    ++counts.lit;
    EXPECT_NEAR(truth.position[k], hit.position, 1e-3) << "line " << k;
    EXPECT_NEAR(truth.depth_m[k], hit.depth, 1e-5) << "line " << k;
    // The truth's own 3-D point lies on the sheet and on the surface.
    const auto [tx, ty] = truth.lines.to_image(k, truth.position[k]);
    const Vec3 r = ray_of(cam, tx, ty);
    const Vec3 p{truth.depth_m[k] * r[0], truth.depth_m[k] * r[1], truth.depth_m[k]};
    EXPECT_NEAR((a * p[0] + b * p[1] + c * p[2] + e) / sheet_norm, 0.0, 1e-5) << "line " << k;
    EXPECT_NEAR(dot3(plane.n, p) - plane.d, 0.0, 1e-5) << "line " << k;
  }
  return counts;
}

// ---- Fitting the rendered line -------------------------------------------------------------

// Sub-pixel centre of the rendered line along line k of an axis-aligned family (columns or rows)
// by a 3-point Gaussian (ln-parabola) fit at the brightest pixel, exact on a noiseless Gaussian
// profile but for rounding to 8 bit; `bound` receives how far that rounding (+-0.5 on each sample,
// to first order) can move it, with the profile's width taken from the fit itself; `sigma` (if
// given) receives that width, exact but for the rounding too.
inline double fit_axis_line(const Image& img, const SimLineFamily& lines, int k, double& bound,
                            double* sigma = nullptr) {
  const int length = lines.along[0] != 0 ? img.width : img.height;
  auto sample = [&](int p) {
    const auto [x, y] = lines.to_image(k, p);
    return img.at(static_cast<int>(std::lround(x)), static_cast<int>(std::lround(y)));
  };
  int best = 0;
  for (int p = 1; p < length; ++p) {
    if (sample(p) > sample(best)) best = p;
  }
  bound = 0;
  if (best == 0 || best == length - 1) return std::nan("");
  const double sa = sample(best - 1), sb = sample(best), sc = sample(best + 1);
  if (sa <= 0 || sc <= 0) return std::nan("");
  const double la = std::log(sa), lb = std::log(sb), lc = std::log(sc);
  const double curvature = la - 2 * lb + lc;  // -1 / sigma^2
  const double s2 = -1.0 / curvature;
  if (sigma != nullptr) *sigma = std::sqrt(s2);
  // delta = (la - lc) / (2 C), C = curvature, |delta| <= 1/2: its derivatives by la, lb and lc,
  // (1 - 2 delta) / (2 C), 2 delta / C and -(1 + 2 delta) / (2 C), are each at most s2 in size,
  // and a sample x rounded by +-0.5 moves ln x by at most 0.5 / x.
  bound = s2 * (0.5 / sa + 0.5 / sb + 0.5 / sc) + 1e-3;
  return best + 0.5 * (la - lc) / (la - 2 * lb + lc);
}

// Solves the n x n system m x = y (Gaussian elimination with partial pivoting).
template <std::size_t N>
inline std::array<double, N> solve(std::array<std::array<double, N>, N> m,
                                   std::array<double, N> y) {
  for (std::size_t i = 0; i < N; ++i) {
    std::size_t pivot = i;
    for (std::size_t r = i + 1; r < N; ++r) {
      if (std::abs(m[r][i]) > std::abs(m[pivot][i])) pivot = r;
    }
    std::swap(m[i], m[pivot]);
    std::swap(y[i], y[pivot]);
    for (std::size_t r = i + 1; r < N; ++r) {
      const double f = m[r][i] / m[i][i];
      for (std::size_t c = i; c < N; ++c)
        m[r][c] -= f * m[i][c];
      y[r] -= f * y[i];
    }
  }
  std::array<double, N> x{};
  for (std::size_t i = N; i-- > 0;) {
    double s = y[i];
    for (std::size_t c = i + 1; c < N; ++c)
      s -= m[i][c] * x[c];
    x[i] = s / m[i][i];
  }
  return x;
}

// Sub-pixel centre of the rendered line along line k of any family, from the pixels themselves:
// for a straight line of light of constant brightness and width (a flat surface of albedo 1, no
// sheet width) ln I is a quadratic in (position, line) near it, which a weighted least-squares fit
// over the pixels within `reach` lines of k recovers; its peak on line k is the centre. Weights
// I^2 (rounding's variance of ln I is 1 / (12 I^2)); `bound` receives the first-order effect of
// +-0.5 rounding on every sample. `guess` is a position near the line's centre; `sigma` (if
// given) receives the profile's width along the line.
inline double fit_any_line(const Image& img, const SimLineFamily& lines, int k, double guess,
                           double reach, double& bound, double* sigma = nullptr) {
  struct Sample {
    double p, l, value;
  };
  std::vector<Sample> samples;
  const auto [gx, gy] = lines.to_image(k, guess);
  const int r = static_cast<int>(std::ceil(reach)) + 12;
  for (int v = static_cast<int>(gy) - r; v <= static_cast<int>(gy) + r; ++v) {
    for (int u = static_cast<int>(gx) - r; u <= static_cast<int>(gx) + r; ++u) {
      if (u < 0 || v < 0 || u >= img.width || v >= img.height) continue;
      const auto [line, position] = lines.to_family(u, v);
      if (std::abs(line - k) > reach || std::abs(position - guess) > 12) continue;
      if (img.at(u, v) < 10) continue;  // rounding dominates the faint tails
      samples.push_back({position - guess, line - k, static_cast<double>(img.at(u, v))});
    }
  }
  bound = 1e300;
  if (samples.size() < 12) return std::nan("");
  // ln I = c0 + c1 p + c2 p^2 + c3 l + c4 l p + c5 l^2.
  auto terms = [](const Sample& s) {
    return std::array<double, 6>{1, s.p, s.p * s.p, s.l, s.l * s.p, s.l * s.l};
  };
  std::array<std::array<double, 6>, 6> normal{};
  std::array<double, 6> rhs{};
  for (const Sample& s : samples) {
    const auto t = terms(s);
    const double w = s.value * s.value;
    for (std::size_t i = 0; i < 6; ++i) {
      rhs[i] += w * t[i] * std::log(s.value);
      for (std::size_t j = 0; j < 6; ++j)
        normal[i][j] += w * t[i] * t[j];
    }
  }
  const auto coef = solve(normal, rhs);
  const double peak = -coef[1] / (2 * coef[2]);
  if (sigma != nullptr) *sigma = std::sqrt(-1 / (2 * coef[2]));  // along the line
  // d peak / d coef = (-1 / (2 c2), c1 / (2 c2^2)) on (c1, c2); through the normal equations to
  // each sample's ln I, whose rounding error is at most 0.5 / I.
  std::array<double, 6> grad{};
  grad[1] = -1 / (2 * coef[2]);
  grad[2] = coef[1] / (2 * coef[2] * coef[2]);
  const auto g = solve(normal, grad);  // the normal matrix is symmetric
  bound = 1e-3;
  for (const Sample& s : samples) {
    const auto t = terms(s);
    double d = 0;
    for (std::size_t i = 0; i < 6; ++i)
      d += g[i] * t[i];
    bound += std::abs(d * s.value * s.value) * 0.5 / s.value;
  }
  return guess + peak;
}

}  // namespace laserline::hal::sim_reference
