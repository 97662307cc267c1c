// Tests of the simulator's features beyond the plain scan (test_sim_scene.cpp): line families,
// colour, turbid water, caustics, marine snow, bright marks, moving objects and panning. Each
// checks the renderer against a computation made here from the options as sim_scene.hpp documents
// them (geometry in closed form or by brute force, light by the stated model), never against the
// renderer's own intermediate numbers.
// Over 600 lines: one unit (the simulator's renderer), a section per feature, sharing the
// reference geometry above them.

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

constexpr double kPi = std::numbers::pi;
constexpr double kDegree = kPi / 180.0;
using namespace sim_reference;

SimGroundTruth truth_along(const SimScene& scene, std::uint64_t sequence, bool laser_on,
                           const SimLineFamily& lines) {
  SimGroundTruth truth;
  scene.ground_truth(sequence, laser_on, lines, truth);
  return truth;
}

// A small scene keeps the tests quick; the camera holds still unless a test moves it.
SimSceneOptions still_options() {
  SimSceneOptions o;
  o.calibration.camera.width = 320;
  o.calibration.camera.height = 256;
  o.calibration.camera.fx = o.calibration.camera.fy = 350;
  o.calibration.camera.cx = 159.5;
  o.calibration.camera.cy = 127.5;
  o.sway_m = 0;
  o.sway_deg = 0;
  return o;
}

// The paper's sheet (projector above the camera) turned by `angle` about the optical axis: its
// normal (0, 1, -tan(90 deg - beta)) rotated in the x-y plane.
std::array<double, 4> turned_sheet(const LaserMount& mount, double angle) {
  const double t = std::tan(kPi / 2 - mount.angle_deg * kDegree);
  return {-std::sin(angle), std::cos(angle), -t, mount.baseline_m};
}

bool same_floats(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!(a[i] == b[i] || (std::isnan(a[i]) && std::isnan(b[i])))) return false;
  }
  return true;
}

bool same_truth(const SimGroundTruth& a, const SimGroundTruth& b) {
  return same_floats(a.position, b.position) && same_floats(a.depth_m, b.depth_m) &&
         same_floats(a.width_px, b.width_px);
}

// ---- Geometry, from the options as the header documents them -----------------------------

// The ray (X/Z, Y/Z, 1) of image point (x, y).
Vec3 ray_of(const CameraIntrinsics& cam, double x, double y) {
  return {(x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0};
}

// A world point in the surface's frame: along e1, along e2, height toward the camera.
Vec3 surface_coordinates(const SurfaceFrame& f, const Vec3& world) {
  const Vec3 d{world[0] - f.origin[0], world[1] - f.origin[1], world[2] - f.origin[2]};
  return {dot3(f.e1, d), dot3(f.e2, d), dot3(f.normal, d)};
}

// The base plane in the camera frame of one frame: n . X = d, n pointing away from the camera.
struct CameraPlane {
  Vec3 n;
  double d;
};

CameraPlane base_plane_in_camera(const SimSceneOptions& o, const SimCameraPose& pose) {
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
double sheet_inverse_depth(const Calibration& c, double x, double y) {
  const auto [a, b, cz, e] = c.laser.plane_coefficients();
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

FlatHit flat_hit(const SimSceneOptions& o, const SimCameraPose& pose, const SimLineFamily& lines,
                 int k) {
  const CameraIntrinsics& cam = o.calibration.camera;
  const auto [a, b, c, e] = o.calibration.laser.plane_coefficients();
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
bool inside_frame(const CameraIntrinsics& cam, const SimLineFamily& lines, double x, double y,
                  double margin, double& slack) {
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

TruthCounts expect_flat_truth_exact(const SimScene& scene, std::uint64_t sequence,
                                    const SimGroundTruth& truth) {
  const SimSceneOptions& o = scene.options();
  const CameraIntrinsics& cam = o.calibration.camera;
  const SimCameraPose pose = scene.camera_pose(sequence);
  const CameraPlane plane = base_plane_in_camera(o, pose);
  const auto [a, b, c, e] = o.calibration.laser.plane_coefficients();
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
double fit_axis_line(const Image& img, const SimLineFamily& lines, int k, double& bound,
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
std::array<double, N> solve(std::array<std::array<double, N>, N> m, std::array<double, N> y) {
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
double fit_any_line(const Image& img, const SimLineFamily& lines, int k, double guess, double reach,
                    double& bound, double* sigma = nullptr) {
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

// ---- Line families ---------------------------------------------------------------------------

TEST(SimSceneLines, FamiliesFollowTheGradientOfTheSheetsInverseDepth) {
  SimSceneOptions o = still_options();
  const CameraIntrinsics& cam = o.calibration.camera;
  // Beside the camera: rows; above or below: columns.
  for (LaserSide side :
       {LaserSide::kAbove, LaserSide::kBelow, LaserSide::kLeft, LaserSide::kRight}) {
    o.calibration.laser.side = side;
    const bool beside = side == LaserSide::kLeft || side == LaserSide::kRight;
    const SimLineFamily lines = epipolar_lines(o.calibration);
    EXPECT_EQ(lines.origin, (std::array<double, 2>{0.0, 0.0})) << to_string(side);
    EXPECT_EQ(lines.line_step,
              (beside ? std::array<double, 2>{0.0, 1.0} : std::array<double, 2>{1.0, 0.0}))
        << to_string(side);
    EXPECT_EQ(lines.along,
              (beside ? std::array<double, 2>{1.0, 0.0} : std::array<double, 2>{0.0, 1.0}))
        << to_string(side);
    EXPECT_EQ(lines.count, beside ? cam.height : cam.width);
    SimScene scene(o);
    EXPECT_EQ(scene.lines().along, lines.along);
    EXPECT_EQ(scene.lines().count, lines.count);
  }

  // A sheet turned about the optical axis, seen by a camera with unequal focal lengths (the
  // gradient is over pixels, not over normalised coordinates). The gradient of 1/Z over the image
  // is taken here by differences of the sheet's inverse depth at three pixels (it is affine).
  o.calibration.camera.fx = 350;
  o.calibration.camera.fy = 280;
  for (double turn_deg : {3.0, 30.0, -30.0, 60.0, 120.0, 88.0, -89.0}) {
    o.calibration.laser.plane = turned_sheet(o.calibration.laser, turn_deg * kDegree);
    const double p00 = sheet_inverse_depth(o.calibration, 100, 100);
    const double gu = sheet_inverse_depth(o.calibration, 101, 100) - p00;
    const double gv = sheet_inverse_depth(o.calibration, 100, 101) - p00;
    const double norm = std::hypot(gu, gv);
    // Columns within 5 degrees of the v axis, rows within 5 degrees of the u axis.
    const double from_v = std::atan2(std::abs(gu), std::abs(gv)) / kDegree;
    const SimLineFamily lines = epipolar_lines(o.calibration);
    SCOPED_TRACE(testing::Message() << "sheet turned " << turn_deg << " deg, gradient " << from_v
                                    << " deg from the v axis");
    if (from_v <= 5) {
      EXPECT_EQ(lines.along, (std::array<double, 2>{0.0, 1.0}));
      EXPECT_EQ(lines.count, cam.width);
      continue;
    }
    if (from_v >= 85) {
      EXPECT_EQ(lines.along, (std::array<double, 2>{1.0, 0.0}));
      EXPECT_EQ(lines.count, cam.height);
      continue;
    }
    // along is the unit gradient (either way round), line_step a unit vector across it.
    EXPECT_NEAR(std::abs(lines.along[0] * gu + lines.along[1] * gv) / norm, 1.0, 1e-12);
    EXPECT_NEAR(std::hypot(lines.line_step[0], lines.line_step[1]), 1.0, 1e-12);
    EXPECT_NEAR(lines.line_step[0] * lines.along[0] + lines.line_step[1] * lines.along[1], 0.0,
                1e-12);
    // Along line_step the sheet's depth stays: every line sees it at the same positions.
    for (double position : {0.0, 50.0, 200.0}) {
      const auto [x0, y0] = lines.to_image(0, position);
      const auto [x1, y1] = lines.to_image(lines.count - 1, position);
      EXPECT_NEAR(sheet_inverse_depth(o.calibration, x0, y0),
                  sheet_inverse_depth(o.calibration, x1, y1), 1e-12);
    }
    // The lines cover the frame: its corners lie on lines 0 .. count - 1 at positions >= 0, and
    // one line more or less would not do.
    double lo = 1e300, hi = -1e300;
    for (double x : {0.0, cam.width - 1.0}) {
      for (double y : {0.0, cam.height - 1.0}) {
        const auto [line, position] = lines.to_family(x, y);
        EXPECT_GE(line, -1e-9);
        EXPECT_LE(line, lines.count - 1 + 1e-9);
        EXPECT_GE(position, -1e-9);
        lo = std::min(lo, line);
        hi = std::max(hi, line);
        // to_image inverts to_family.
        const auto [bx, by] = lines.to_image(line, position);
        EXPECT_NEAR(bx, x, 1e-9);
        EXPECT_NEAR(by, y, 1e-9);
      }
    }
    EXPECT_LT(lo, 1.0);
    EXPECT_GT(hi, lines.count - 2.0);
    SimScene scene(o);
    EXPECT_EQ(scene.lines().along, lines.along);
    EXPECT_EQ(scene.lines().origin, lines.origin);
    EXPECT_EQ(scene.lines().count, lines.count);
  }
}

TEST(SimSceneLines, TruthAlongRowsIsExactForALaserBesideTheCamera) {
  for (LaserSide side : {LaserSide::kLeft, LaserSide::kRight}) {
    SCOPED_TRACE(to_string(side));
    SimSceneOptions o = laser_only(still_options());
    o.calibration.laser.side = side;
    o.tilt_x_deg = 12;
    o.tilt_y_deg = -20;
    SimScene scene(o);
    const SimGroundTruth truth = truth_of(scene, 0, true);
    ASSERT_EQ(truth.lines.along, (std::array<double, 2>{1.0, 0.0}));
    const TruthCounts counts = expect_flat_truth_exact(scene, 0, truth);
    EXPECT_EQ(counts.lit, o.calibration.camera.height);  // the line runs down the whole frame

    // The rendered line's centre, fitted along each row, is the truth.
    const Image img = render(scene, 0, true);
    double worst = 0;
    for (int k = 0; k < truth.lines.count; ++k) {
      double bound = 0;
      const double fit = fit_axis_line(img, truth.lines, k, bound);
      EXPECT_NEAR(fit, truth.position[k], bound) << "row " << k;
      worst = std::max(worst, std::abs(fit - truth.position[k]));
    }
    std::printf("  %s: worst |fit - truth| over %d rows: %.4f px\n", to_string(side),
                truth.lines.count, worst);

    // The truth's width is the profile's across the line: its sigma along rows.
    o.calibration.laser.sheet_width_m = 0.01;
    o.blur_px = 0.5;
    SimScene wide(o);
    const SimGroundTruth t2 = truth_of(wide, 0, true);
    const Image wide_img = render(wide, 0, true);
    double ratio = 0;
    for (int k = 0; k < t2.lines.count; ++k) {
      const double sheet = o.calibration.camera.fx * o.calibration.laser.sheet_width_m /
                           t2.depth_m[k] / (2 * std::sqrt(2 * std::log(2.0)));
      EXPECT_NEAR(t2.width_px[k], std::hypot(sheet, o.blur_px), 1e-4) << "row " << k;
      double bound = 0, sigma = 0;
      (void)fit_axis_line(wide_img, t2.lines, k, bound, &sigma);
      ratio += sigma / t2.width_px[k] / t2.lines.count;
    }
    // And it is the rendered profile's: the fitted sigma, on average over the rows (rounding
    // moves each fit's curvature by a few per cent, either way).
    std::printf("  %s: fitted sigma / truth's width %.4f (width about %.2f px)\n", to_string(side),
                ratio, t2.width_px[100]);
    EXPECT_NEAR(ratio, 1.0, 0.01);
  }
}

TEST(SimSceneLines, TruthIsNaNWithinOnePointFivePixelsOfTheEdgesTheLinesCross) {
  // A laser beside the camera: the rows cross the left and right edges, not the top and bottom.
  // The line is placed at column x by the distance: x = cx + fx (t - d / Z) for the left side.
  SimSceneOptions o = laser_only(still_options());
  o.calibration.laser.side = LaserSide::kLeft;
  o.calibration.laser.angle_deg = 60;
  const CameraIntrinsics& cam = o.calibration.camera;
  const double t = std::tan(kPi / 2 - o.calibration.laser.angle_deg * kDegree);
  for (double column :
       {0.3, 1.2, 1.45, 1.55, 2.5, cam.width - 2.7, cam.width - 2.45, cam.width - 1.8}) {
    o.distance_m = o.calibration.laser.baseline_m / (t - (column - cam.cx) / cam.fx);
    SimScene scene(o);
    const SimGroundTruth truth = truth_of(scene, 0, true);
    const bool inside = column >= 1.5 && column <= cam.width - 2.5;
    EXPECT_EQ(finite_count(truth.position), inside ? cam.height : 0) << "column " << column;
    EXPECT_EQ(finite_count(truth.depth_m), inside ? cam.height : 0);
    if (inside) {
      // Rows 0 and height - 1 are lines like any other: the top and bottom edges are not crossed.
      EXPECT_NEAR(truth.position.front(), column, 1e-3);
      EXPECT_NEAR(truth.position.back(), column, 1e-3);
    }
    // And the line is drawn all the same.
    const int nearest = static_cast<int>(std::lround(column));
    EXPECT_GT(render(scene, 0, true).at(nearest, 100), 100) << "column " << column;
  }

  // Turned 30 degrees about the optical axis and on a tilted surface, the lit line runs
  // obliquely through the frame and leaves it; line by line the truth is NaN exactly where the
  // closed-form point lies outside the frame or within 1.5 px of an edge (both axes: the lines
  // cross both).
  o = laser_only(still_options());
  o.calibration.laser.plane = turned_sheet(o.calibration.laser, 30 * kDegree);
  o.tilt_y_deg = 15;
  int at_edge = 0;
  for (double distance : {1.2, 0.9, 2.0}) {
    o.distance_m = distance;
    SimScene scene(o);
    ASSERT_NE(scene.lines().along[0], 0.0);
    ASSERT_NE(scene.lines().along[1], 0.0);
    const TruthCounts counts = expect_flat_truth_exact(scene, 0, truth_of(scene, 0, true));
    EXPECT_GT(counts.lit, 100);
    at_edge += counts.at_edge;
  }
  EXPECT_GE(at_edge, 3);  // the margin was tested, not only points far outside
}

TEST(SimSceneLines, TruthIsExactAlongTheRenderersObliqueFamilyAndAlongOthers) {
  // The sheet turned 30 degrees about the optical axis: the renderer draws along its oblique
  // family. A straight line of light of constant brightness and width (no sheet width) lets the
  // centre be fitted on any line from the pixels (fit_any_line).
  SimSceneOptions o = laser_only(still_options());
  o.calibration.laser.plane = turned_sheet(o.calibration.laser, 30 * kDegree);
  o.calibration.laser.sheet_width_m = 0;
  o.blur_px = 1.5;
  o.tilt_x_deg = -10;
  o.tilt_y_deg = 20;
  SimScene scene(o);
  const SimLineFamily own = scene.lines();
  ASSERT_GT(std::abs(own.along[0]), 0.3);  // oblique indeed
  const Image img = render(scene, 0, true);

  // Along the renderer's own lines.
  const SimGroundTruth truth = truth_of(scene, 0, true);
  TruthCounts counts = expect_flat_truth_exact(scene, 0, truth);
  EXPECT_GT(counts.lit, 200);
  int used = 0;
  double worst = 0, widest = 0, width_ratio = 0;
  for (int k = 0; k < own.count; ++k) {
    if (!std::isfinite(truth.position[k])) continue;
    const auto [x, y] = own.to_image(k, truth.position[k]);
    if (x < 8 || y < 8 || x > img.width - 9 || y > img.height - 9) continue;  // whole fit window
    double bound = 0, sigma = 0;
    const double fit = fit_any_line(img, own, k, truth.position[k], 3.0, bound, &sigma);
    EXPECT_NEAR(fit, truth.position[k], bound) << "line " << k;
    width_ratio += sigma / truth.width_px[k];
    worst = std::max(worst, std::abs(fit - truth.position[k]));
    widest = std::max(widest, bound);
    ++used;
  }
  width_ratio /= used;
  std::printf(
      "  oblique family: %d lines fitted, worst |fit - truth| %.4f px (bounds <= %.4f), fitted "
      "width / truth's %.4f\n",
      used, worst, widest, width_ratio);
  // The truth's width is the rendered profile's along the lines (on average over them: rounding
  // moves each fit's curvature by a few per cent, either way).
  EXPECT_NEAR(width_ratio, 1.0, 0.01);
  EXPECT_GT(used, 150);
  EXPECT_LT(widest, 0.05);  // the bound is tight enough to mean something

  // Along columns and rows, which are not the renderer's: the line crosses them at 30 and 60
  // degrees, and its profile along each is still a Gaussian (of another width).
  for (const bool columns : {true, false}) {
    SimLineFamily lines;
    if (columns) {
      lines = SimLineFamily::columns(img.width);
    } else {
      lines.line_step = {0.0, 1.0};
      lines.along = {1.0, 0.0};
      lines.count = img.height;
    }
    const SimGroundTruth other = truth_along(scene, 0, true, lines);
    EXPECT_EQ(other.lines.count, lines.count);
    counts = expect_flat_truth_exact(scene, 0, other);
    EXPECT_GT(counts.lit, columns ? 250 : 100);
    used = 0;
    worst = 0;
    width_ratio = 0;
    for (int k = 0; k < lines.count; ++k) {
      if (!std::isfinite(other.position[k])) continue;
      double bound = 0, sigma = 0;
      const double fit = fit_axis_line(img, lines, k, bound, &sigma);
      EXPECT_NEAR(fit, other.position[k], bound) << (columns ? "column " : "row ") << k;
      worst = std::max(worst, std::abs(fit - other.position[k]));
      width_ratio += sigma / other.width_px[k];
      ++used;
    }
    width_ratio /= used;
    std::printf("  along %s: %d fitted, worst |fit - truth| %.4f px, fitted width / truth's %.4f\n",
                columns ? "columns" : "rows", used, worst, width_ratio);
    EXPECT_EQ(used, counts.lit);
    // Along lines crossing the line of light obliquely its profile is wider: the truth's width is
    // that of the profile along these lines.
    EXPECT_NEAR(width_ratio, 1.0, 0.01);
  }
}

// ---- Colour ----------------------------------------------------------------------------------

// A scene with everything that lights it: textured surface, caustics, veiling light, backscatter,
// forward scatter and marine snow, below 8-bit saturation everywhere.
SimSceneOptions busy_options() {
  SimSceneOptions o = still_options();
  o.sway_m = 0.02;
  o.sway_deg = 0.5;
  o.tilt_y_deg = 10;
  o.laser_peak = 130;
  o.backscatter = 15;
  o.attenuation_per_m = 0.1;
  o.forward_scatter = 0.3;
  o.veiling = 0.25;
  o.caustic_peak = 3;
  o.snow_per_frame = 40;
  o.snow_brightness = 0.5;
  o.seed = 3;
  return o;
}

TEST(SimSceneColour, RawFormatAndSizeFollowTheColour) {
  SimSceneOptions o = still_options();
  const std::size_t pixels = 320u * 256u;
  const std::pair<SimColour, PixelLayout> cases[] = {
      {SimColour::kMono, PixelLayout::kMono},
      {SimColour::kRgb, PixelLayout::kRgb},
      {SimColour::kBayerRggb, PixelLayout::kBayerRggb},
      {SimColour::kBayerGrbg, PixelLayout::kBayerGrbg},
      {SimColour::kBayerGbrg, PixelLayout::kBayerGbrg},
      {SimColour::kBayerBggr, PixelLayout::kBayerBggr}};
  for (const auto& [colour, layout] : cases) {
    o.colour = colour;
    SimScene scene(o);
    EXPECT_EQ(scene.raw_format().layout, layout);
    EXPECT_EQ(scene.raw_format().bits, 8);
    EXPECT_EQ(scene.raw_bytes(), colour == SimColour::kRgb ? 3 * pixels : pixels);
    // The pipeline's frame stays mono8 whatever the camera delivers.
    EXPECT_EQ(scene.format().pixel_format, PixelFormat::kMono8);
    EXPECT_EQ(scene.format().bytes(), pixels);
    std::vector<std::uint8_t> short_buffer(scene.raw_bytes() - 1);
    EXPECT_THROW(scene.render(0, true, short_buffer), std::invalid_argument);
  }
  auto rejects = [](auto change) {
    SimSceneOptions bad = still_options();
    change(bad);
    EXPECT_THROW(SimScene{bad}, std::invalid_argument);
  };
  rejects([](SimSceneOptions& b) { b.laser_rgb[1] = -0.1; });
  rejects([](SimSceneOptions& b) { b.ambient_rgb[2] = std::nan(""); });
  rejects([](SimSceneOptions& b) { b.ambient_rgb[0] = 11; });
}

TEST(SimSceneColour, EachChannelIsTheMonoFramesAmbientAndLaserLightInItsShare) {
  // Mono frames give the two lights apart: the ambient light A alone (laser off) and the laser's
  // light L alone (ambient 0: the line, its halo, the glow and the snow). Noiseless, a channel
  // with factors a and l is round(a A + l L).
  SimSceneOptions o = busy_options();
  o.noise_sigma = 0;
  SimScene mono(o);
  SimSceneOptions no_ambient = o;
  no_ambient.ambient = 0;
  SimScene laser_light(no_ambient);
  const std::uint64_t seq = 7;
  const Image ambient_only = render(mono, seq, false);
  const Image laser_only_img = render(laser_light, seq, true);

  // Factors 0 and 1 make two channels the mono frames bit for bit; factors 1/2 the mono frame of
  // a scene at half the light (scaling by 2 is exact in floating point, only the order of the
  // sums differs: at most one grey level, rarely).
  o.colour = SimColour::kRgb;
  o.ambient_rgb = {1.0, 0.0, 0.5};
  o.laser_rgb = {0.0, 1.0, 0.5};
  SimScene rgb(o);
  const Image frame = render(rgb, seq, true);
  SimSceneOptions half = busy_options();
  half.noise_sigma = 0;
  half.ambient /= 2;
  half.laser_peak /= 2;
  half.backscatter /= 2;
  SimScene half_light(half);
  const Image half_frame = render(half_light, seq, true);
  ASSERT_EQ(frame.channels, 3);
  int differ = 0, lit = 0, worst = 0;
  for (int v = 0; v < frame.height; ++v) {
    for (int u = 0; u < frame.width; ++u) {
      ASSERT_EQ(frame.at(u, v, 0), ambient_only.at(u, v)) << u << ", " << v;
      ASSERT_EQ(frame.at(u, v, 1), laser_only_img.at(u, v)) << u << ", " << v;
      const int d = std::abs(frame.at(u, v, 2) - half_frame.at(u, v));
      worst = std::max(worst, d);
      differ += d != 0 ? 1 : 0;
      lit += laser_only_img.at(u, v) > 0 ? 1 : 0;
    }
  }
  std::printf("  blue = half the mono light: %d of %d pixels one level off\n", differ,
              frame.width * frame.height);
  EXPECT_LE(worst, 1);
  EXPECT_LT(differ, frame.width * frame.height / 100);
  EXPECT_GT(lit, 5000);  // line, halo, glow and snow were all in the comparison

  // Any factors: each channel is a A + l L to within the rounding of the three frames.
  o.ambient_rgb = {0.9, 0.7, 0.4};
  o.laser_rgb = {0.08, 1.0, 0.12};
  SimScene coloured(o);
  const Image c = render(coloured, seq, true);
  for (int v = 0; v < c.height; ++v) {
    for (int u = 0; u < c.width; ++u) {
      ASSERT_LT(ambient_only.at(u, v) + laser_only_img.at(u, v), 255);  // no clipping anywhere
      for (int ch = 0; ch < 3; ++ch) {
        const double a = o.ambient_rgb[ch], l = o.laser_rgb[ch];
        const double model = a * ambient_only.at(u, v) + l * laser_only_img.at(u, v);
        ASSERT_NEAR(c.at(u, v, ch), model, 0.5 + 0.5 * (a + l) + 1e-6)
            << u << ", " << v << " channel " << ch;
      }
    }
  }
}

TEST(SimSceneColour, ChannelNoiseIsIndependentWithTheRequestedSigma) {
  // A flat grey surface (albedo 1, ambient 100: no rounding of the light itself), white light:
  // every channel is 100 + its own noise. Each channel's deviation has variance sigma^2 + 1/12
  // (rounding); two channels' difference twice that; their correlation 0. Over n = 81920 pixels
  // a sample standard deviation is good to about 1 / sqrt(2 n) = 0.25 % and a correlation to
  // 1 / sqrt(n) = 0.0035: the tolerances are some 6 times those. The mean is good to
  // sigma / sqrt(n) = 0.01 (4 times that allowed); sigma is such that no noise sample (a multiple
  // of sigma / 16) lands on half a grey level, which rounding half up would bias by 1/32 level at
  // sigma = 3.
  SimSceneOptions o = still_options();
  o.colour = SimColour::kRgb;
  o.texture_contrast = 0;
  o.ambient = 100;
  o.noise_sigma = 2.93;
  o.ambient_rgb = {1, 1, 1};
  SimScene scene(o);
  const Image img = render(scene, 4, false);
  const double n = static_cast<double>(img.width) * img.height;
  std::array<double, 3> mean{}, var{};
  std::array<std::array<double, 3>, 3> cov{};
  for (int v = 0; v < img.height; ++v) {
    for (int u = 0; u < img.width; ++u) {
      for (int a = 0; a < 3; ++a) {
        const double da = img.at(u, v, a) - 100.0;
        mean[a] += da / n;
        for (int b = 0; b < 3; ++b)
          cov[a][b] += da * (img.at(u, v, b) - 100.0) / n;
      }
    }
  }
  const double expected = std::sqrt(o.noise_sigma * o.noise_sigma + 1.0 / 12);
  for (int a = 0; a < 3; ++a) {
    var[a] = cov[a][a] - mean[a] * mean[a];
    std::printf("  channel %d: mean %+.4f, sd %.4f (expected %.4f)\n", a, mean[a],
                std::sqrt(var[a]), expected);
    EXPECT_NEAR(mean[a], 0.0, 0.04) << "channel " << a;
    EXPECT_NEAR(std::sqrt(var[a]), expected, 0.05 * expected) << "channel " << a;
  }
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3;
    const double c = cov[a][b] - mean[a] * mean[b];
    const double difference = std::sqrt(var[a] + var[b] - 2 * c);
    std::printf("  channels %d and %d: correlation %.4f, sd of difference %.3f\n", a, b,
                c / std::sqrt(var[a] * var[b]), difference);
    EXPECT_NEAR(c / std::sqrt(var[a] * var[b]), 0.0, 0.02);
    EXPECT_NEAR(difference, std::sqrt(2.0) * expected, 0.05 * expected);
  }
}

TEST(SimSceneColour, BayerFramesCarryTheRgbFramesSampleOfEachPixelsColour) {
  // All four mosaics, named by their top-left 2x2 cell read row by row; the same options and seed
  // as an RGB frame, noise included: each pixel is that frame's sample of its own colour.
  SimSceneOptions o = busy_options();
  o.noise_sigma = 2;
  o.colour = SimColour::kRgb;
  SimScene rgb(o);
  const std::uint64_t seq = 12;
  const Image full = render(rgb, seq, true);
  const SimGroundTruth rgb_truth = truth_of(rgb, seq, true);
  const std::pair<SimColour, const char*> mosaics[] = {{SimColour::kBayerRggb, "RGGB"},
                                                       {SimColour::kBayerGrbg, "GRBG"},
                                                       {SimColour::kBayerGbrg, "GBRG"},
                                                       {SimColour::kBayerBggr, "BGGR"}};
  for (const auto& [colour, cell] : mosaics) {
    o.colour = colour;
    SimScene bayer(o);
    const Image mosaic = render(bayer, seq, true);
    ASSERT_EQ(mosaic.channels, 1);
    for (int v = 0; v < mosaic.height; ++v) {
      for (int u = 0; u < mosaic.width; ++u) {
        const char name = cell[(v % 2) * 2 + u % 2];
        const int channel = name == 'R' ? 0 : name == 'G' ? 1 : 2;
        ASSERT_EQ(mosaic.at(u, v), full.at(u, v, channel)) << cell << " at " << u << ", " << v;
      }
    }
    EXPECT_TRUE(same_truth(truth_of(bayer, seq, true), rgb_truth)) << cell;
  }
  // Nor does the truth depend on colour at all.
  o.colour = SimColour::kMono;
  o.laser_rgb = {1, 0.08, 0.03};
  SimScene mono(o);
  EXPECT_TRUE(same_truth(truth_of(mono, seq, true), rgb_truth));
  EXPECT_GT(finite_count(rgb_truth.position), 250);
}

// ---- Turbid water ----------------------------------------------------------------------------

TEST(SimSceneTurbidity, ForwardScatterKeepsTheLinesEnergyAndCentreAndSpreadsItIntoTheHalo) {
  // The paper's mounting, a slanted line on a textured surface, sensor noise. The laser's light in
  // a column is the lit frame minus the dark one (the same frame number: the same noise, which
  // cancels); what is left of the rounding is, per pixel, round(x + L) - round(x) - L: zero mean,
  // |e| < 1, variance at most 1/4. Sums over the 2 * 45 + 1 rows around the line are good to
  // sqrt(91 / 4) per column, their mean over n columns to sqrt(91 / (4 n)).
  SimSceneOptions o = still_options();
  o.tilt_y_deg = 10;
  o.texture_contrast = 0.15;
  o.ambient = 20;
  o.laser_peak = 180;  // with the brightest texture and the noise, below 255
  o.noise_sigma = 2;
  SimScene clear(o);
  o.forward_scatter = 0.5;
  o.scatter_halo_px = 8;
  SimScene turbid(o);
  const std::uint64_t seq = 5;
  const SimGroundTruth truth = truth_of(clear, seq, true);
  ASSERT_TRUE(same_truth(truth, truth_of(turbid, seq, true)));  // the truth is the core's
  const Image clear_lit = render(clear, seq, true), clear_dark = render(clear, seq, false);
  const Image turbid_lit = render(turbid, seq, true), turbid_dark = render(turbid, seq, false);
  ASSERT_EQ(clear_dark.data, turbid_dark.data);

  constexpr int kHalfBand = 45;  // 5 halo sigmas and more
  const int width = clear_lit.width;
  double energy_clear = 0, energy_turbid = 0, centre_error = 0, centre_var = 0;
  double halo_inner = 0, halo_outer = 0, model_inner = 0, model_outer = 0;
  int columns = 0;
  for (int u = 0; u < width; ++u) {
    const double c = truth.position[u], sigma = truth.width_px[u];
    ASSERT_TRUE(std::isfinite(c));
    const int v0 = static_cast<int>(std::lround(c));
    ASSERT_GE(v0 - kHalfBand, 0);
    ASSERT_LT(v0 + kHalfBand, clear_lit.height);
    double e0 = 0, e1 = 0, moment = 0, spread = 0;
    for (int v = v0 - kHalfBand; v <= v0 + kHalfBand; ++v) {
      const double l0 = clear_lit.at(u, v) - clear_dark.at(u, v);
      const double l1 = turbid_lit.at(u, v) - turbid_dark.at(u, v);
      ASSERT_LT(turbid_lit.at(u, v), 255);
      ASSERT_LT(clear_lit.at(u, v), 255);
      e0 += l0;
      e1 += l1;
      moment += (v - c) * l1;
      spread += (v - c) * (v - c) / 4;
    }
    // Per column: the energies agree to 5 standard deviations of their difference.
    EXPECT_NEAR(e1, e0, 5 * std::sqrt(2 * (2 * kHalfBand + 1) / 4.0)) << "column " << u;
    energy_clear += e0;
    energy_turbid += e1;
    centre_error += moment / e1;
    centre_var += spread / (e1 * e1);
    // The halo: a Gaussian of sigma hypot(sigma, scatter_halo_px) holding forward_scatter of the
    // energy, whose peak follows from the clear line's energy (peak * sigma * sqrt(2 pi)). At 4
    // core sigmas and more the core has nothing left.
    const double halo_sigma = std::hypot(sigma, o.scatter_halo_px);
    const double halo_peak = o.forward_scatter * e0 / (halo_sigma * std::sqrt(2 * kPi));
    for (int v = v0 - kHalfBand; v <= v0 + kHalfBand; ++v) {
      const double d = std::abs(v - c);
      if (d < 4) continue;
      const double model = halo_peak * std::exp(-d * d / (2 * halo_sigma * halo_sigma));
      const double seen = turbid_lit.at(u, v) - turbid_dark.at(u, v);
      (d < 12 ? model_inner : model_outer) += model;
      (d < 12 ? halo_inner : halo_outer) += seen;
    }
    ++columns;
  }
  energy_clear /= columns;
  energy_turbid /= columns;
  centre_error /= columns;
  const double energy_sd = std::sqrt(2 * (2 * kHalfBand + 1) / 4.0 / columns);
  const double centre_sd = std::sqrt(centre_var) / columns;
  std::printf(
      "  line energy per column: %.2f clear, %.2f turbid (sd of the difference %.2f); centre "
      "error %+.4f px (sd %.4f); halo inner %.0f of %.0f, outer %.0f of %.0f\n",
      energy_clear, energy_turbid, energy_sd, centre_error, centre_sd, halo_inner, model_inner,
      halo_outer, model_outer);
  EXPECT_NEAR(energy_turbid, energy_clear, 4 * energy_sd);
  EXPECT_NEAR(centre_error, 0.0, 4 * centre_sd);
  // The halo is there, as wide as said: each of its two zones within 5 % (the sums are of
  // thousands of pixels, their rounding far below that; the core's estimate of the peak is good
  // to about 2 %).
  EXPECT_NEAR(halo_inner, model_inner, 0.05 * model_inner);
  EXPECT_NEAR(halo_outer, model_outer, 0.05 * model_outer);
  EXPECT_GT(model_outer, 0.2 * model_inner);
}

TEST(SimSceneTurbidity, VeilingLowersTheContrastByItsShareAndKeepsTheMean) {
  // Veiling light v: each pixel's ambient light A + (1 - v) (light - A), A the ambient light on
  // albedo 1: the texture's deviations from A shrink by 1 - v, and the mean stays while the
  // texture's mean albedo is 1. Noiseless: per pixel to within the rounding of both frames.
  SimSceneOptions o = still_options();
  o.noise_sigma = 0;
  o.ambient = 80;
  o.texture_contrast = 0.5;
  o.caustic_peak = 2;  // caustic light veils alike
  SimScene clear(o);
  o.veiling = 0.4;
  SimScene veiled(o);
  const std::uint64_t seq = 3;
  const Image a = render(clear, seq, false), b = render(veiled, seq, false);
  const double n = static_cast<double>(a.data.size());
  double mean_a = 0, mean_b = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    const double expected = o.ambient + (1 - o.veiling) * (a.data[i] - o.ambient);
    ASSERT_NEAR(b.data[i], expected, 0.5 + 0.5 * (1 - o.veiling) + 1e-9) << "pixel " << i;
    mean_a += a.data[i] / n;
    mean_b += b.data[i] / n;
  }
  double var_a = 0, var_b = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    var_a += (a.data[i] - mean_a) * (a.data[i] - mean_a) / n;
    var_b += (b.data[i] - mean_b) * (b.data[i] - mean_b) / n;
  }
  std::printf("  mean %.2f -> %.2f, sd %.2f -> %.2f (x %.3f)\n", mean_a, mean_b, std::sqrt(var_a),
              std::sqrt(var_b), std::sqrt(var_b / var_a));
  // Rounding adds variance 1/12 to each frame (which the texture's variance dwarfs).
  EXPECT_NEAR(std::sqrt(var_b / var_a), 1 - o.veiling, 0.01);
  EXPECT_NEAR(mean_b, mean_a, 0.02 * o.ambient);
  EXPECT_NEAR(mean_b - mean_a, o.veiling * (o.ambient - mean_a), 0.5);

  // The laser's light is not veiled: lit minus dark is the same in both waters.
  const Image la = render(clear, seq, true), lb = render(veiled, seq, true);
  int lit = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    if (la.data[i] == 255 || lb.data[i] == 255) continue;  // clipped
    const int line_a = la.data[i] - a.data[i], line_b = lb.data[i] - b.data[i];
    // Each difference is the line's light to within (-1, 1): they differ by at most 1.
    ASSERT_LE(std::abs(line_a - line_b), 1) << "pixel " << i;
    lit += line_a > 20 ? 1 : 0;
  }
  EXPECT_GT(lit, 320);
}

TEST(SimSceneTurbidity, BackscatterStaysOnTheCameraSideOfTheLineForEveryFamily) {
  // A pixel can glow only where its ray crosses the sheet before the surface: 0 < Z_sheet <
  // Z_surface, both computed here per pixel. Where that fails for the pixel and its eight
  // neighbours (the renderer decides per line, to within a pixel), the frame is the clear water's
  // bit for bit; on the camera's side it is brighter. Rows (the laser beside the camera) and the
  // oblique family, on a tilted surface (the columns: test_sim_scene.cpp).
  for (const bool oblique : {false, true}) {
    SCOPED_TRACE(oblique ? "oblique" : "rows");
    SimSceneOptions o = still_options();
    if (oblique) {
      o.calibration.laser.plane = turned_sheet(o.calibration.laser, -35 * kDegree);
    } else {
      o.calibration.laser.side = LaserSide::kRight;
    }
    o.tilt_x_deg = 15;
    o.tilt_y_deg = -12;
    o.attenuation_per_m = 0.2;
    SimScene clear(o);
    o.backscatter = 30;
    SimScene turbid(o);
    const std::uint64_t seq = 2;
    const Image a = render(clear, seq, true), b = render(turbid, seq, true);
    const CameraIntrinsics& cam = o.calibration.camera;
    const CameraPlane plane = base_plane_in_camera(o, clear.camera_pose(seq));
    auto near_side = [&](int u, int v) {
      const double p = sheet_inverse_depth(o.calibration, u, v);
      const double q = dot3(plane.n, ray_of(cam, u, v)) / plane.d;  // the surface's 1/Z
      return p > 0 && p > q;
    };
    int far = 0, near = 0;
    double brightening = 0;
    for (int v = 1; v + 1 < a.height; ++v) {
      for (int u = 1; u + 1 < a.width; ++u) {
        int near_count = 0;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du)
            near_count += near_side(u + du, v + dv) ? 1 : 0;
        }
        if (near_count == 0) {
          ASSERT_EQ(a.at(u, v), b.at(u, v)) << "far side " << u << ", " << v;
          ++far;
        } else if (near_count == 9) {
          brightening += b.at(u, v) - a.at(u, v);
          ++near;
        }
      }
    }
    std::printf("  %d pixels on the far side unchanged; %d on the camera's side %.1f brighter\n",
                far, near, brightening / near);
    EXPECT_GT(far, 10000);
    EXPECT_GT(near, 10000);
    EXPECT_GT(brightening / near, 2.0);
    EXPECT_EQ(render(clear, seq, false).data, render(turbid, seq, false).data);
  }
}

// ---- Caustics ---------------------------------------------------------------------------------

TEST(SimSceneCaustics, KeepTheMeanAmbientLightAndPeakAtCausticPeak) {
  // A flat grey surface (albedo 1), noiseless: each pixel is round(ambient * caustic light). Over
  // eight frames a second apart (the pattern drifts by 0.2 m, two cells, between them) and some
  // 100 cells in each, the mean light is the ambient light. How well: the curves hold about 3 %
  // of the light pattern's area, varying by about that much from cell to cell, so the mean of the
  // caustic light over N cells varies by about (peak - 1) * 0.03 / sqrt(N), under 1 % here for
  // N = 8 * 100; allowed 3 %. Not keeping the mean (the curves added on top) would add some 15 %.
  SimSceneOptions o = still_options();
  o.noise_sigma = 0;
  o.texture_contrast = 0;
  o.ambient = 40;
  o.caustic_peak = 6;
  o.caustic_scale_m = 0.1;
  SimScene scene(o);
  double mean = 0, brightest = 0;
  int frames = 0;
  for (std::uint64_t seq = 0; seq < 240; seq += 30) {
    const Image img = render(scene, seq, false);
    double sum = 0;
    for (std::uint8_t p : img.data) {
      sum += p;
      brightest = std::max(brightest, static_cast<double>(p));
    }
    mean += sum / static_cast<double>(img.data.size());
    ++frames;
  }
  mean /= frames;
  std::printf("  mean light %.2f of ambient %.0f; brightest %.0f = %.2f x the mean (peak %.0f)\n",
              mean, o.ambient, brightest, brightest / mean, o.caustic_peak);
  EXPECT_NEAR(mean, o.ambient, 0.03 * o.ambient);
  // The brightest light is caustic_peak times the ambient light (where the curves of the
  // pattern meet), never more but for rounding.
  EXPECT_LE(brightest, o.caustic_peak * o.ambient + 0.5);
  EXPECT_GE(brightest, 0.85 * o.caustic_peak * o.ambient);
}

TEST(SimSceneCaustics, KeepTheMeanUpToTheHighestPeakAllowed) {
  // The pattern's curves cover a few per cent of the surface: a caustic_peak beyond 1 / (that
  // share) cannot keep the mean with light between the curves that is >= 0; the options allow up
  // to 100. To see the caustic light f from 0 to 100 times the mean in 8 bit: ambient light A =
  // 4.9 half veiled, each pixel A / 2 (f + 1) (from 2.45 to 247.45), noise of sigma 0.6 dithering
  // the rounding (a pixel would be clipped below 0 at -2.95 levels, 4.9 sigma, about 5e-7 of them;
  // none reach 255). The mean of f is good to a few per cent over eight frames and some 800 cells
  // (see above).
  for (const double peak : {40.0, 100.0}) {
    SimSceneOptions o = still_options();
    o.noise_sigma = 0.6;
    o.texture_contrast = 0;
    o.ambient = 4.9;
    o.veiling = 0.5;
    o.caustic_peak = peak;
    o.caustic_scale_m = 0.1;
    const double half = o.ambient / 2;
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
      o.seed = seed;
      SimScene scene(o);
      double mean = 0, brightest = 0;
      int frames = 0;
      for (std::uint64_t seq = 0; seq < 240; seq += 30) {
        const Image img = render(scene, seq, false);
        double sum = 0;
        for (std::uint8_t p : img.data) {
          sum += p;
          brightest = std::max(brightest, static_cast<double>(p));
        }
        mean += sum / static_cast<double>(img.data.size());
        ++frames;
      }
      const double f_mean = (mean / frames - half) / half, f_max = (brightest - half) / half;
      std::printf("  peak %.0f, seed %d: mean caustic light %.3f, brightest %.1f\n", peak,
                  static_cast<int>(seed), f_mean, f_max);
      EXPECT_NEAR(f_mean, 1.0, 0.04) << "peak " << peak << ", seed " << seed;
      EXPECT_LE(f_max, peak + 4.8 / half);  // the noise: at most 127 / 16 sigma
      // The thinner the curves, the rarer a pixel on the very crossing of two.
      EXPECT_GE(f_max, 0.7 * peak);
    }
  }
}

TEST(SimSceneCaustics, ThePatternDriftsOverTheStillTextureAndLeavesTheLineAlone) {
  // A still camera: the textured surface stays pixel for pixel while the caustics move over it.
  SimSceneOptions o = still_options();
  o.noise_sigma = 0;
  o.ambient = 40;
  o.texture_contrast = 0.5;
  SimScene plain(o);
  o.caustic_peak = 4;
  o.caustic_speed_m_s = 0.3;
  SimScene caustic(o);
  SimSceneOptions flat = o;
  flat.texture_contrast = 0;  // the caustic light alone, times the ambient light
  SimScene light(flat);
  const std::uint64_t a = 10, b = 13;  // 0.1 s: the pattern moves by some 3 cm
  const Image plain_a = render(plain, a, false), plain_b = render(plain, b, false);
  ASSERT_EQ(plain_a.data, plain_b.data);
  const Image light_a = render(light, a, false), light_b = render(light, b, false);
  const Image caustic_a = render(caustic, a, false), caustic_b = render(caustic, b, false);
  // The caustic light multiplies the texture where it is: round(A albedo f) against the rounded
  // round(A albedo) and round(A f) of the other two frames.
  for (const auto& [lit, texture_lit] : {std::pair{&light_a, &caustic_a}, {&light_b, &caustic_b}}) {
    for (std::size_t i = 0; i < plain_a.data.size(); ++i) {
      const double f = lit->data[i], p = plain_a.data[i];
      if (f == 255 || texture_lit->data[i] == 255) continue;
      ASSERT_NEAR(texture_lit->data[i], f * p / o.ambient,
                  0.5 + (0.5 * f + 0.5 * p + 0.25) / o.ambient + 1e-9)
          << "pixel " << i;
    }
  }
  // ... and moved between the frames.
  double moved = 0;
  for (std::size_t i = 0; i < light_a.data.size(); ++i)
    moved += std::abs(light_a.data[i] - light_b.data[i]);
  moved /= static_cast<double>(light_a.data.size());
  std::printf("  caustic light moved: mean |difference| %.2f grey levels in 0.1 s\n", moved);
  EXPECT_GT(moved, 2.0);

  // Where it is depends on speed * time alone: still at speed 0, the same at twice the speed and
  // half the time (bit for bit: scaling by 2 is exact).
  flat.caustic_speed_m_s = 0;
  SimScene still(flat);
  EXPECT_EQ(render(still, a, false).data, render(still, b, false).data);
  flat.caustic_speed_m_s = 2 * o.caustic_speed_m_s;
  SimScene fast(flat);
  EXPECT_EQ(render(fast, 7, false).data, render(light, 14, false).data);
  EXPECT_NE(render(fast, 7, false).data, render(light, 7, false).data);

  // The laser's light is not the ambient light: lit minus dark is the same with caustics.
  const Image plain_lit = render(plain, a, true), caustic_lit = render(caustic, a, true);
  for (std::size_t i = 0; i < plain_a.data.size(); ++i) {
    if (plain_lit.data[i] == 255 || caustic_lit.data[i] == 255) continue;
    ASSERT_LE(
        std::abs((caustic_lit.data[i] - caustic_a.data[i]) - (plain_lit.data[i] - plain_a.data[i])),
        1)
        << "pixel " << i;
  }
}

TEST(SimSceneCaustics, PeakOneIsNoCausticsWhateverTheOtherCausticOptions) {
  SimSceneOptions o = still_options();
  o.sway_m = 0.02;
  o.backscatter = 10;
  SimScene plain(o);
  o.caustic_peak = 1;
  o.caustic_scale_m = 0.37;
  o.caustic_speed_m_s = -3;
  SimScene none(o);
  EXPECT_EQ(render(plain, 17, true).data, render(none, 17, true).data);
  EXPECT_EQ(render(plain, 18, false).data, render(none, 18, false).data);
  auto rejects = [](auto change) {
    SimSceneOptions bad = still_options();
    change(bad);
    EXPECT_THROW(SimScene{bad}, std::invalid_argument);
  };
  rejects([](SimSceneOptions& b) { b.caustic_peak = 0.5; });
  rejects([](SimSceneOptions& b) { b.caustic_scale_m = 0; });
  rejects([](SimSceneOptions& b) { b.caustic_speed_m_s = std::nan(""); });
}

// ---- Marine snow -----------------------------------------------------------------------------

struct Spot {
  int u, v, peak;
};

// The local maxima of at least `threshold` in an image of added light (ties broken toward the
// first in row order).
std::vector<Spot> find_spots(const std::vector<int>& light, int width, int height, int threshold) {
  std::vector<Spot> spots;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const int x = light[static_cast<std::size_t>(v) * width + u];
      if (x < threshold) continue;
      bool peak = true;
      for (int dv = -1; dv <= 1 && peak; ++dv) {
        for (int du = -1; du <= 1 && peak; ++du) {
          const int uu = u + du, vv = v + dv;
          if ((du == 0 && dv == 0) || uu < 0 || vv < 0 || uu >= width || vv >= height) continue;
          const int y = light[static_cast<std::size_t>(vv) * width + uu];
          const bool before = dv < 0 || (dv == 0 && du < 0);
          peak = before ? x > y : x >= y;
        }
      }
      if (peak) spots.push_back({u, v, x});
    }
  }
  return spots;
}

TEST(SimSceneSnow, SpotsLieInTheSheetInFrontOfTheSurfaceNewEachFrameAndOnlyWithTheLaser) {
  // The snow's light is the snowy frame minus the clear one (the same frame: the same noise).
  // Each spot's centre must see the sheet nearer than the surface along its ray (Z computed here
  // per pixel; within a pixel, the 3 x 3 around the brightest) and no nearer than
  // snow_min_depth_m; all the added light must belong to the spots.
  struct Mount {
    const char* name;
    LaserSide side;
    double turn_deg;  // the sheet turned about the optical axis (0: the side's own model)
  };
  for (const Mount& mount :
       {Mount{"above", LaserSide::kAbove, 0.0}, Mount{"right", LaserSide::kRight, 0.0},
        Mount{"turned", LaserSide::kAbove, 30.0}}) {
    SCOPED_TRACE(mount.name);
    SimSceneOptions o = still_options();
    o.calibration.laser.side = mount.side;
    if (mount.turn_deg != 0)
      o.calibration.laser.plane = turned_sheet(o.calibration.laser, mount.turn_deg * kDegree);
    o.tilt_x_deg = 8;
    o.tilt_y_deg = -10;
    o.texture_contrast = 0.3;
    o.laser_peak = 150;
    o.noise_sigma = 2;
    SimScene clear(o);
    o.snow_per_frame = 25;
    o.snow_size_px = 1.2;
    o.snow_brightness = 0.8;
    o.snow_min_depth_m = 0.5;  // the sheet is in the frame from 0.46 m on (paper's mounting)
    SimScene snowy(o);
    const CameraIntrinsics& cam = o.calibration.camera;
    const CameraPlane plane = base_plane_in_camera(o, clear.camera_pose(0));
    auto sheet_depth = [&](int u, int v) {
      const double p = sheet_inverse_depth(o.calibration, u, v);
      return p > 0 ? 1.0 / p : 1e300;
    };
    std::vector<std::vector<Spot>> frames;
    for (std::uint64_t seq : {4u, 5u}) {
      ASSERT_EQ(render(snowy, seq, false).data, render(clear, seq, false).data);
      ASSERT_TRUE(same_truth(truth_of(snowy, seq, true), truth_of(clear, seq, true)));
      const Image s = render(snowy, seq, true), c = render(clear, seq, true);
      std::vector<int> light(s.data.size());
      for (std::size_t i = 0; i < light.size(); ++i) {
        light[i] = s.data[i] - c.data[i];
        ASSERT_GE(light[i], 0) << "pixel " << i;  // light added, never taken
      }
      const std::vector<Spot> spots = find_spots(light, s.width, s.height, 8);
      double nearest = 1e300, farthest = 0;
      for (const Spot& spot : spots) {
        double lo = 1e300, hi = 0;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            lo = std::min(lo, sheet_depth(spot.u + du, spot.v + dv));
            hi = std::max(hi, sheet_depth(spot.u + du, spot.v + dv));
          }
        }
        const double surface = plane.d / dot3(plane.n, ray_of(cam, spot.u, spot.v));
        EXPECT_LT(lo, surface) << "spot at " << spot.u << ", " << spot.v << " behind the surface";
        EXPECT_GE(hi, o.snow_min_depth_m) << "spot at " << spot.u << ", " << spot.v;
        EXPECT_LE(spot.peak, o.snow_brightness * o.laser_peak + 1);
        nearest = std::min(nearest, lo);
        farthest = std::max(farthest, hi / surface);
      }
      // All the added light is the spots' (Gaussians of sigma up to 1.4 snow_size_px, drawn to
      // 4 sigma), or a spot's hidden in the saturated line.
      const double reach = 4 * 1.4 * o.snow_size_px + 1;
      int stray = 0;
      for (int v = 0; v < s.height; ++v) {
        for (int u = 0; u < s.width; ++u) {
          if (light[static_cast<std::size_t>(v) * s.width + u] == 0) continue;
          bool near_spot = false;
          for (const Spot& spot : spots)
            near_spot = near_spot || std::hypot(u - spot.u, v - spot.v) <= reach;
          // A spot on the line can be hidden where the line saturates: its tails remain.
          for (int dv = -8; dv <= 8 && !near_spot; ++dv) {
            for (int du = -8; du <= 8 && !near_spot; ++du) {
              const int uu = u + du, vv = v + dv;
              near_spot = uu >= 0 && vv >= 0 && uu < s.width && vv < s.height &&
                          s.at(uu, vv) == 255 && std::hypot(du, dv) <= reach;
            }
          }
          stray += near_spot ? 0 : 1;
        }
      }
      EXPECT_EQ(stray, 0);
      std::printf("  %s, frame %d: %zu spots, sheet depths %.2f m to %.2f of the surface's\n",
                  mount.name, static_cast<int>(seq), spots.size(), nearest, farthest);
      // Two spots can merge into one; particles falling outside the frame are not drawn.
      EXPECT_LE(static_cast<int>(spots.size()), o.snow_per_frame);
      EXPECT_GE(static_cast<int>(spots.size()),
                mount.turn_deg == 0 ? o.snow_per_frame - 3 : o.snow_per_frame / 2);
      frames.push_back(spots);
    }
    // New snow each frame: hardly a spot in the same place.
    int same = 0;
    for (const Spot& a : frames[0]) {
      for (const Spot& b : frames[1])
        same += a.u == b.u && a.v == b.v ? 1 : 0;
    }
    EXPECT_LE(same, 2);
    // Deterministic per seed and frame, whatever was rendered before; another seed, other snow.
    SimScene again(o);
    EXPECT_EQ(render(again, 4, true).data, render(snowy, 4, true).data);
    (void)render(snowy, 9, true);
    EXPECT_EQ(render(snowy, 5, true).data, render(again, 5, true).data);
    o.seed = 77;
    SimScene other(o);
    o.snow_per_frame = 0;
    SimScene other_clear(o);
    EXPECT_NE(render(other, 4, true).data, render(other_clear, 4, true).data);
  }
}

// ---- Bright marks ----------------------------------------------------------------------------

TEST(SimSceneMarks, MarksOfTheirAlbedoAppearAtTheRequestedDensityAndNowhereElse) {
  // A camera seeing the surface square on at exactly one texel (texture_scale_m / 4 = 2.5 mm) a
  // pixel, pixel centres on texel centres: each pixel is one texel's albedo times the ambient
  // light. 1024 x 1024 pixels are 2.56 m x 2.56 m of surface.
  SimSceneOptions o = still_options();
  o.calibration.camera.width = o.calibration.camera.height = 1024;
  o.calibration.camera.fx = o.calibration.camera.fy = 480;  // 1.2 m / 480 = 2.5 mm a pixel
  o.calibration.camera.cx = o.calibration.camera.cy = 512;
  o.noise_sigma = 0;
  o.ambient = 80;
  o.texture_contrast = 0.5;  // albedo at most 1.5 (120), marks at least 0.6 * 3 (144)
  SimScene plain(o);
  SimSceneOptions zero = o;
  zero.marks_albedo = 7;
  SimScene no_marks(zero);
  const Image before = render(plain, 0, false);
  ASSERT_EQ(before.data, render(no_marks, 0, false).data);  // zero marks: bit for bit as before
  o.marks_per_m2 = 50;
  SimScene marked(o);
  const Image after = render(marked, 0, false);
  const int w = after.width, h = after.height;
  const double pixel_m = 1.2 / 480;

  // Mark pixels: changed by more than the 1 grey level that float rounding of the texel
  // coordinates can move a neighbour. Their grey is ambient * marks_albedo * [0.6, 1].
  std::vector<int> label(after.data.size(), -1);
  auto mark = [&](int u, int v) {
    const std::size_t i = static_cast<std::size_t>(v) * w + u;
    return after.data[i] - before.data[i] >= 2;
  };
  const double lo = o.ambient * o.marks_albedo * 0.6, hi = o.ambient * o.marks_albedo;
  int changed = 0;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      if (mark(u, v)) {
        ++changed;
        ASSERT_GE(after.data[i], lo - 1) << u << ", " << v;
        ASSERT_LE(after.data[i], hi + 1) << u << ", " << v;
        continue;
      }
      // Elsewhere the texture is as it was (next to a mark to within that 1 level).
      bool beside = false;
      for (int dv = -1; dv <= 1; ++dv) {
        for (int du = -1; du <= 1; ++du) {
          const int uu = u + du, vv = v + dv;
          beside = beside || (uu >= 0 && vv >= 0 && uu < w && vv < h && mark(uu, vv));
        }
      }
      ASSERT_LE(std::abs(after.data[i] - before.data[i]), beside ? 1 : 0) << u << ", " << v;
    }
  }

  // Marks are the 8-connected pieces of mark pixels; those touching the frame's edge may be
  // parts of marks and are not counted. Expected: marks_per_m2 times the area, less the marks
  // cut by the edge (those within a mark's size, some 3 cm, of it: about 4 * 2.56 * 0.03 / 6.55,
  // 5 %) and those merged with another (their area is about 1 % of the surface): between 85 %
  // and 100 %.
  int marks = 0, single_valued = 0, longest = 0;
  int darkest = 255, brightest = 0;
  for (int v0 = 0; v0 < h; ++v0) {
    for (int u0 = 0; u0 < w; ++u0) {
      if (!mark(u0, v0) || label[static_cast<std::size_t>(v0) * w + u0] >= 0) continue;
      std::vector<std::pair<int, int>> stack{{u0, v0}}, piece;
      label[static_cast<std::size_t>(v0) * w + u0] = 1;
      bool edge = false;
      while (!stack.empty()) {
        const auto [u, v] = stack.back();
        stack.pop_back();
        piece.push_back({u, v});
        edge = edge || u == 0 || v == 0 || u == w - 1 || v == h - 1;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            const int uu = u + du, vv = v + dv;
            if (uu < 0 || vv < 0 || uu >= w || vv >= h || !mark(uu, vv)) continue;
            int& l = label[static_cast<std::size_t>(vv) * w + uu];
            if (l < 0) {
              l = 1;
              stack.push_back({uu, vv});
            }
          }
        }
      }
      if (edge) continue;
      ++marks;
      const int grey = after.at(piece[0].first, piece[0].second);
      bool one_value = true;
      int umin = w, umax = 0, vmin = h, vmax = 0;
      for (const auto& [u, v] : piece) {
        one_value = one_value && after.at(u, v) == grey;
        umin = std::min(umin, u), umax = std::max(umax, u);
        vmin = std::min(vmin, v), vmax = std::max(vmax, v);
      }
      if (!one_value) continue;  // overlapping marks
      ++single_valued;
      darkest = std::min(darkest, grey);
      brightest = std::max(brightest, grey);
      longest = std::max(longest, std::max(umax - umin, vmax - vmin) + 1);
    }
  }
  const double area = w * pixel_m * h * pixel_m;
  const double expected = o.marks_per_m2 * area;
  std::printf(
      "  %d marks inside the frame (%.0f expected on %.2f m^2), %d of one albedo: grey %d to %d, "
      "longest %d px; %.2f %% of the surface\n",
      marks, expected, area, single_valued, darkest, brightest, longest, 100.0 * changed / (w * h));
  EXPECT_GE(marks, 0.85 * expected);
  EXPECT_LE(marks, expected);
  EXPECT_GE(single_valued, 0.9 * marks);
  // Albedos spread over marks_albedo * [0.6, 1]: with some 300 marks the extremes are near.
  EXPECT_LE(darkest, lo + 0.04 * (hi - lo));
  EXPECT_GE(brightest, hi - 0.04 * (hi - lo));
  // No mark is longer than the longest stroke, 8 cm (32 px) and its width.
  EXPECT_LE(longest, 0.08 / pixel_m + 4);
  EXPECT_GT(longest, 0.05 / pixel_m);
}

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
  const double step = 0.001 / std::sqrt(dot3(ray, ray));
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
  return point(0.5 * (lo + hi));
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
    double lo = 0, hi = 0;
    double previous = sheet_side(u, 0);
    for (int v = 1; v < o.calibration.camera.height; ++v) {
      const double side = sheet_side(u, v);
      if ((side > 0) != (previous > 0)) {
        ++crossings;
        lo = v - 1;
        hi = v;
      }
      previous = side;
    }
    ASSERT_EQ(crossings, 1) << "column " << u << ": the line must be seen once";
    const bool lo_positive = sheet_side(u, lo) > 0;
    for (int i = 0; i < 40; ++i) {
      const double mid = 0.5 * (lo + hi);
      ((sheet_side(u, mid) > 0) == lo_positive ? lo : hi) = mid;
    }
    const double row = 0.5 * (lo + hi);
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
