// The simulator's line families: which way the lines run (the gradient of the sheet's inverse
// depth), and their ground truth along rows, near edges and along oblique families.
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

}  // namespace
}  // namespace laserline::hal
