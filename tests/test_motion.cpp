// MotionEstimator: homography accuracy against frames warped by a known homography (OpenCV does
// the warping, only here), the laser filter with a line that stays while the scene moves, invalid
// estimates, no allocation in update(), and sizes too small for the pyramid.
// Over 600 lines: one unit (the motion stage), on shared warped and rendered frames.
#include "pipeline/motion.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "allocation_counter.hpp"
#include "hal/sim/sim_scene.hpp"

namespace laserline::pipeline {
namespace {

constexpr int kWidth = 1280;
constexpr int kHeight = 1024;

ImageView view_of(const cv::Mat& image) {
  return ImageView{image.ptr<std::uint8_t>(0), image.cols, image.rows,
                   static_cast<int>(image.step[0])};
}

// A simulated underwater frame, laser off: the product's own scene renderer.
cv::Mat sim_texture() {
  hal::SimSceneOptions o;
  o.calibration.camera.width = kWidth;
  o.calibration.camera.height = kHeight;
  o.tilt_y_deg = 8;
  hal::SimScene scene(o);
  cv::Mat image(kHeight, kWidth, CV_8UC1);
  scene.render(0, false, {image.ptr<std::uint8_t>(0), image.total()});
  return image;
}

// Smoothed uniform noise: a plain random texture with no structure at all.
cv::Mat random_texture() {
  cv::Mat noise(kHeight, kWidth, CV_8UC1);
  cv::RNG rng(12345);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
  cv::Mat smooth;
  cv::GaussianBlur(noise, smooth, cv::Size(0, 0), 2.0);
  // Stretch the contrast the blur took away.
  cv::Mat stretched;
  smooth.convertTo(stretched, CV_8UC1, 4.0, -3.0 * 128);
  return stretched;
}

cv::Mat warp(const cv::Mat& image, const cv::Matx33d& h) {
  cv::Mat out;
  cv::warpPerspective(image, out, h, image.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  return out;
}

cv::Matx33d rotation_about_centre(double degrees) {
  const double a = degrees * CV_PI / 180.0, c = std::cos(a), s = std::sin(a);
  const double x0 = (kWidth - 1) / 2.0, y0 = (kHeight - 1) / 2.0;
  return cv::Matx33d(c, -s, x0 - c * x0 + s * y0, s, c, y0 - s * x0 - c * y0, 0, 0, 1);
}

// A mild perspective change about the centre plus a shift: a few pixels at the corners.
cv::Matx33d perspective_warp() {
  const double x0 = (kWidth - 1) / 2.0, y0 = (kHeight - 1) / 2.0;
  const cv::Matx33d to_centre(1, 0, -x0, 0, 1, -y0, 0, 0, 1);
  const cv::Matx33d back(1, 0, x0 + 2.5, 0, 1, y0 - 1.5, 0, 0, 1);
  const cv::Matx33d p(1.002, 0.001, 0, -0.0015, 0.999, 0, 6e-6, -5e-6, 1);
  return back * p * to_centre;
}

// Largest distance between the estimate and the truth over a grid covering the image.
double max_grid_error(const Homography& estimate, const cv::Matx33d& truth) {
  double worst = 0;
  for (int j = 0; j <= 8; ++j) {
    for (int i = 0; i <= 8; ++i) {
      const double u = 0.05 * kWidth + 0.9 * kWidth * i / 8.0;
      const double v = 0.05 * kHeight + 0.9 * kHeight * j / 8.0;
      const cv::Vec3d t = truth * cv::Vec3d(u, v, 1);
      const auto e = estimate.map(u, v);
      worst = std::max(worst, std::hypot(e[0] - t[0] / t[2], e[1] - t[1] / t[2]));
    }
  }
  return worst;
}

MotionEstimate estimate_pair(MotionEstimator& estimator, const cv::Mat& first,
                             const cv::Mat& second) {
  estimator.reset(first.cols, first.rows);
  const MotionEstimate none = estimator.update(view_of(first));
  EXPECT_FALSE(none.valid) << "the first frame after reset() has nothing to compare with";
  return estimator.update(view_of(second));
}

void print(const char* name, const MotionEstimate& e, double grid_error) {
  std::printf(
      "%-28s valid %d detected %3d rejected %2d tracked %3d inliers %3d rms %.3f px, "
      "max grid error %.4f px\n",
      name, e.valid, e.detected, e.rejected_on_laser, e.tracked, e.inliers, e.rms_px, grid_error);
}

struct WarpCase {
  const char* name;
  cv::Matx33d h;
};

std::vector<WarpCase> warp_cases() {
  return {{"translation", cv::Matx33d(1, 0, 7.3, 0, 1, -4.6, 0, 0, 1)},
          {"rotation 1 deg", rotation_about_centre(1.0)},
          {"perspective", perspective_warp()}};
}

TEST(MotionEstimator, RecoversKnownHomographyOfSimulatedScene) {
  const cv::Mat first = sim_texture();
  MotionEstimator estimator;
  for (const WarpCase& c : warp_cases()) {
    const MotionEstimate e = estimate_pair(estimator, first, warp(first, c.h));
    const double error = max_grid_error(e.previous_to_current, c.h);
    print((std::string("sim scene, ") + c.name).c_str(), e, error);
    ASSERT_TRUE(e.valid) << c.name;
    EXPECT_GE(e.inliers, 100) << c.name;
    EXPECT_LT(error, 0.1) << c.name;
  }
}

TEST(MotionEstimator, RecoversKnownHomographyOfRandomTexture) {
  const cv::Mat first = random_texture();
  MotionEstimator estimator;
  for (const WarpCase& c : warp_cases()) {
    const MotionEstimate e = estimate_pair(estimator, first, warp(first, c.h));
    const double error = max_grid_error(e.previous_to_current, c.h);
    print((std::string("random texture, ") + c.name).c_str(), e, error);
    ASSERT_TRUE(e.valid) << c.name;
    EXPECT_GE(e.inliers, 100) << c.name;
    EXPECT_LT(error, 0.1) << c.name;
  }
}

// Other option values: no pyramid, deep pyramids, the largest window, a coarse grid.
TEST(MotionEstimator, WorksWithOtherOptions) {
  const cv::Mat first = random_texture();
  struct Case {
    int levels, detect_level, radius, columns, rows;
    cv::Matx33d h;
  };
  const Case cases[] = {
      {1, 0, 4, 16, 12, cv::Matx33d(1, 0, 1.3, 0, 1, -0.8, 0, 0, 1)},
      {5, 3, 7, 12, 9, rotation_about_centre(1.5)},
      {3, 1, 15, 16, 12, perspective_warp()},
      {4, 0, 2, 32, 24, cv::Matx33d(1, 0, 7.3, 0, 1, -4.6, 0, 0, 1)},
  };
  for (const Case& c : cases) {
    MotionOptions o;
    o.pyramid_levels = c.levels;
    o.detect_level = c.detect_level;
    o.window_radius = c.radius;
    o.grid_columns = c.columns;
    o.grid_rows = c.rows;
    MotionEstimator estimator(o);
    const MotionEstimate e = estimate_pair(estimator, first, warp(first, c.h));
    const double error = max_grid_error(e.previous_to_current, c.h);
    char name[64];
    std::snprintf(name, sizeof name, "levels %d detect %d r %d", c.levels, c.detect_level,
                  c.radius);
    print(name, e, error);
    ASSERT_TRUE(e.valid) << name;
    EXPECT_LT(error, 0.1) << name;
  }
}

// Draws a bright horizontal laser line centred on `row`, modulated by the surface brightness as
// a real line on a textured surface is (the simulator's ambient 40 against a laser peak of 180).
void draw_laser_line(cv::Mat& image, double row, double sigma_px) {
  for (int v = 0; v < image.rows; ++v) {
    const double d = (v - row) / sigma_px;
    const double gain = 1.0 + 4.5 * std::exp(-0.5 * d * d);
    if (gain < 1.001) continue;
    std::uint8_t* p = image.ptr<std::uint8_t>(v);
    for (int u = 0; u < image.cols; ++u)
      p[u] = static_cast<std::uint8_t>(std::min(255.0, std::round(p[u] * gain)));
  }
}

int count_near_row(std::span<const std::array<float, 2>> points, double row, double distance) {
  return static_cast<int>(std::count_if(points.begin(), points.end(), [&](const auto& p) {
    return std::abs(p[1] - row) <= distance;
  }));
}

// A PTU tilt: the scene moves vertically, the laser line stays on the same rows.
TEST(MotionEstimator, LaserFilterRejectsFeaturesOnAStaticLine) {
  const cv::Mat scene = sim_texture();
  const cv::Matx33d tilt(1, 0, 0.4, 0, 1, 6.5, 0, 0, 1);
  cv::Mat first = scene.clone();
  cv::Mat second = warp(scene, tilt);
  // Near: within the line's reach at the detect level (a 2-px line blurred over 4 px blocks).
  const double line_row = 517.3, near_px = 16.0;
  draw_laser_line(first, line_row, 2.0);
  draw_laser_line(second, line_row, 2.0);

  // Where the features of the first frame lie: kept and rejected by the filter, and all of them
  // without it.
  MotionEstimator filtered;
  const MotionEstimate e = estimate_pair(filtered, first, second);
  std::vector<std::array<float, 2>> kept;
  for (const FeatureTrack& t : filtered.tracks())
    kept.push_back({t.previous_u, t.previous_v});
  const auto rejected = filtered.rejected_features();

  MotionOptions no_filter_options;
  no_filter_options.laser_filter_ratio = 1e9;
  MotionEstimator unfiltered(no_filter_options);
  const MotionEstimate u = estimate_pair(unfiltered, first, second);
  std::vector<std::array<float, 2>> all;
  for (const FeatureTrack& t : unfiltered.tracks())
    all.push_back({t.previous_u, t.previous_v});

  const double error = max_grid_error(e.previous_to_current, tilt);
  print("laser line, filter on", e, error);
  print("laser line, filter off", u, max_grid_error(u.previous_to_current, tilt));
  const int rejected_near = count_near_row(rejected, line_row, near_px);
  const int kept_near = count_near_row(kept, line_row, near_px);
  const int all_near = count_near_row(all, line_row, near_px);
  std::printf(
      "rejected %zu (%d near the line); tracked near the line: %d with filter, %d without\n",
      rejected.size(), rejected_near, kept_near, all_near);

  ASSERT_TRUE(e.valid);
  EXPECT_EQ(e.rejected_on_laser, static_cast<int>(rejected.size()));
  EXPECT_EQ(u.rejected_on_laser, 0);
  ASSERT_GE(rejected.size(), 4u) << "the filter should see the line";
  EXPECT_GE(rejected_near, static_cast<int>(0.8 * static_cast<double>(rejected.size())))
      << "most rejected features should lie on the line";
  EXPECT_LT(kept_near, all_near);
  EXPECT_LT(error, 0.2);
}

TEST(MotionEstimator, InvalidForFirstFrameAndBlankFrames) {
  const cv::Mat textured = sim_texture();
  MotionEstimator estimator;
  estimator.reset(kWidth, kHeight);
  const MotionEstimate first = estimator.update(view_of(textured));
  EXPECT_FALSE(first.valid);
  EXPECT_EQ(first.detected, 0) << "no previous frame to report on";
  EXPECT_TRUE(estimator.tracks().empty());
  EXPECT_TRUE(estimator.rejected_features().empty());
  EXPECT_TRUE(estimator.update(view_of(textured)).valid) << "the same frame twice is identity";

  const cv::Mat blank(kHeight, kWidth, CV_8UC1, cv::Scalar(90));
  estimator.reset(kWidth, kHeight);
  EXPECT_FALSE(estimator.update(view_of(blank)).valid);
  const MotionEstimate pair = estimator.update(view_of(blank));
  EXPECT_FALSE(pair.valid);
  EXPECT_EQ(pair.detected, 0);
  EXPECT_EQ(pair.tracked, 0);

  // Textured after blank: the blank frame had no features to track.
  EXPECT_FALSE(estimator.update(view_of(textured)).valid);
}

TEST(MotionEstimator, SameInputSameResult) {
  const cv::Mat first = sim_texture();
  const cv::Mat second = warp(first, rotation_about_centre(0.7));
  MotionEstimator a, b;
  const MotionEstimate ea = estimate_pair(a, first, second);
  const MotionEstimate eb = estimate_pair(b, first, second);
  ASSERT_TRUE(ea.valid);
  EXPECT_EQ(ea.previous_to_current.h, eb.previous_to_current.h);
  EXPECT_EQ(ea.inliers, eb.inliers);
}

TEST(MotionEstimator, UpdateDoesNotAllocate) {
  const cv::Mat first = sim_texture();
  const cv::Mat second = warp(first, rotation_about_centre(0.5));
  cv::Mat with_line = second.clone();
  draw_laser_line(with_line, 300.0, 2.0);
  const cv::Mat blank(kHeight, kWidth, CV_8UC1, cv::Scalar(0));
  MotionEstimator estimator;
  estimator.reset(kWidth, kHeight);
  estimator.update(view_of(first));

  ASSERT_TRUE(testing::allocation_counter_works());
  int valid = 0;
  testing::start_counting_allocations();
  for (const cv::Mat* frame : std::initializer_list<const cv::Mat*>{&second, &first, &with_line,
                                                                    &blank, &first, &second}) {
    valid += estimator.update(view_of(*frame)).valid ? 1 : 0;
  }
  EXPECT_EQ(testing::stop_counting_allocations().count, 0);
  EXPECT_GE(valid, 3);
}

TEST(MotionEstimator, TooSmallImagesAreRefusedByReset) {
  MotionEstimator estimator;
  try {
    estimator.reset(40, 30);
    FAIL() << "reset(40, 30) should throw";
  } catch (const std::invalid_argument& e) {
    const std::string message = e.what();
    std::printf("%s\n", message.c_str());
    EXPECT_NE(message.find("40x30"), std::string::npos);
    EXPECT_NE(message.find("too small"), std::string::npos);
    EXPECT_NE(message.find("pyramid"), std::string::npos);
  }
  EXPECT_THROW(estimator.reset(0, 100), std::invalid_argument);
  EXPECT_THROW(estimator.reset(-5, 100), std::invalid_argument);

  // A grid too fine for the detect level.
  MotionOptions fine;
  fine.grid_columns = 64;
  fine.grid_rows = 64;
  MotionEstimator fine_grid(fine);
  try {
    fine_grid.reset(320, 240);
    FAIL() << "a 64x64 grid on 320x240 should be refused";
  } catch (const std::invalid_argument& e) {
    std::printf("%s\n", e.what());
    EXPECT_NE(std::string(e.what()).find("feature grid"), std::string::npos);
  }

  // Bad options are refused at construction, naming the option.
  MotionOptions bad;
  bad.detect_level = 4;
  bad.pyramid_levels = 4;
  try {
    MotionEstimator refused(bad);
    FAIL() << "detect_level 4 of 4 levels should be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("detect_level"), std::string::npos);
  }

  // update() before reset() or with a frame of another size: invalid, no crash.
  const cv::Mat small(30, 40, CV_8UC1, cv::Scalar(7));
  MotionEstimator unset;
  EXPECT_FALSE(unset.update(view_of(small)).valid);
  estimator.reset(kWidth, kHeight);
  EXPECT_FALSE(estimator.update(view_of(small)).valid);
  EXPECT_FALSE(estimator.update(ImageView{}).valid);

  // A refused reset() leaves nothing half sized: frames of the earlier size are refused too.
  const cv::Mat textured = random_texture();
  EXPECT_THROW(estimator.reset(40, 30), std::invalid_argument);
  EXPECT_FALSE(estimator.update(view_of(textured)).valid);
  EXPECT_FALSE(estimator.update(view_of(textured)).valid);
  EXPECT_TRUE(estimator.tracks().empty());

  // The smallest size the default options take (a 16x12 grid inside a border of 12 at level 2)
  // works; one pixel less is refused.
  EXPECT_THROW(estimator.reset(159, 144), std::invalid_argument);
  EXPECT_THROW(estimator.reset(160, 143), std::invalid_argument);
  estimator.reset(160, 144);
  const cv::Mat tiny = random_texture()(cv::Rect(100, 100, 160, 144)).clone();
  EXPECT_FALSE(estimator.update(view_of(tiny)).valid);
  const MotionEstimate same = estimator.update(view_of(tiny));
  ASSERT_TRUE(same.valid) << "the same frame twice";
  const auto centre = same.previous_to_current.map(80, 72);
  EXPECT_NEAR(centre[0], 80, 0.05);
  EXPECT_NEAR(centre[1], 72, 0.05);
}

TEST(Homography, InverseUndoesTheMapping) {
  Homography h;
  const cv::Matx33d m = perspective_warp() * rotation_about_centre(3.0);
  for (int i = 0; i < 9; ++i)
    h.h(i) = m.val[i];
  const Homography inverse = h.inverse();
  for (const auto& p : {std::array<double, 2>{0, 0}, {1279, 0}, {640.5, 511.5}, {17, 1000}}) {
    const auto q = h.map(p[0], p[1]);
    const auto back = inverse.map(q[0], q[1]);
    EXPECT_NEAR(back[0], p[0], 1e-9);
    EXPECT_NEAR(back[1], p[1], 1e-9);
  }
  EXPECT_DOUBLE_EQ(inverse.h(2, 2), 1.0);
}

// ---------------------------------------------------------------------------------------------
// Camera motion (essential matrix) from synthetic correspondences: 3-D points seen by a camera
// with lens distortion (projected by OpenCV, an independent reference), known R and t.

namespace camera_motion {

struct Pose {
  cv::Matx33d r = cv::Matx33d::eye();  // world -> camera
  cv::Vec3d t{0, 0, 0};
};

ScannerGeometry distorted_geometry() {
  ScannerGeometry g;
  g.width = kWidth;
  g.height = kHeight;
  g.fx = 1500;
  g.fy = 1490;
  g.cx = 641.0;
  g.cy = 509.5;
  g.distortion = {-0.12, 0.05, 0.0008, -0.0005, 0.01};
  return g;
}

cv::Matx33d rotation(double ax_deg, double ay_deg, double az_deg) {
  cv::Mat r;
  cv::Rodrigues(cv::Vec3d(ax_deg, ay_deg, az_deg) * (CV_PI / 180.0), r);
  return cv::Matx33d(r);
}

// Angle of the rotation a^T b, degrees.
double angle_between(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a.t() * b;
  const double c = std::clamp((cv::trace(d) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

double angle_between(const cv::Vec3d& a, const cv::Vec3d& b) {
  const double c = std::clamp(a.dot(b) / (cv::norm(a) * cv::norm(b)), -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

cv::Matx33d rotation_of(const CameraMotion& m) {
  cv::Matx33d r;
  cv::eigen2cv(m.rotation, r);
  return r;
}
cv::Vec3d translation_of(const CameraMotion& m) {
  return {m.translation(0), m.translation(1), m.translation(2)};
}

// Points in front of the first camera, 1.2 .. 3 m deep, spread over the image.
std::vector<cv::Point3d> scene_points(int count, cv::RNG& rng) {
  std::vector<cv::Point3d> points;
  for (int i = 0; i < count; ++i) {
    const double z = rng.uniform(1.2, 3.0);
    points.emplace_back(rng.uniform(-0.38, 0.38) * z, rng.uniform(-0.3, 0.3) * z, z);
  }
  return points;
}

// Pixels (distorted) of the world points seen from `pose`, with Gaussian noise.
std::vector<cv::Point2f> project(const std::vector<cv::Point3d>& points, const Pose& pose,
                                 const ScannerGeometry& g, double noise_px, cv::RNG& rng) {
  cv::Mat rvec;
  cv::Rodrigues(cv::Mat(pose.r), rvec);
  const cv::Matx33d k(g.fx, 0, g.cx, 0, g.fy, g.cy, 0, 0, 1);
  std::vector<double> distortion(g.distortion.begin(), g.distortion.end());
  std::vector<cv::Point2d> pixels;
  cv::projectPoints(points, rvec, cv::Mat(pose.t), k, distortion, pixels);
  std::vector<cv::Point2f> out;
  for (const cv::Point2d& p : pixels) {
    out.emplace_back(static_cast<float>(p.x + rng.gaussian(noise_px)),
                     static_cast<float>(p.y + rng.gaussian(noise_px)));
  }
  return out;
}

std::vector<FeatureTrack> pair_tracks(const std::vector<cv::Point2f>& previous,
                                      const std::vector<cv::Point2f>& current) {
  std::vector<FeatureTrack> tracks;
  for (std::size_t i = 0; i < previous.size(); ++i)
    tracks.push_back({previous[i].x, previous[i].y, current[i].x, current[i].y, false});
  return tracks;
}

// Relative motion camera a -> camera b: X_b = R X_a + t.
Pose relative(const Pose& a, const Pose& b) {
  return {b.r * a.r.t(), b.t - b.r * a.r.t() * a.t};
}

}  // namespace camera_motion

TEST(FivePoint, OneSolutionIsTheTrueEssentialMatrix) {
  using namespace camera_motion;
  cv::RNG rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose second{
        rotation(rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0)),
        cv::Vec3d(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-0.5, 0.5))};
    const std::vector<cv::Point3d> points = scene_points(5, rng);
    std::array<std::array<double, 2>, 5> a, b;
    for (int k = 0; k < 5; ++k) {
      const cv::Vec3d p(points[k].x, points[k].y, points[k].z);
      const cv::Vec3d q = second.r * p + second.t;
      a[k] = {p[0] / p[2], p[1] / p[2]};
      b[k] = {q[0] / q[2], q[1] / q[2]};
    }
    const cv::Vec3d t = second.t / cv::norm(second.t);
    const cv::Matx33d tx(0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0);
    const cv::Matx33d truth = tx * second.r * (1.0 / cv::norm(tx * second.r));
    std::array<std::array<double, 9>, 10> solutions;
    const int count = five_point_essentials(a, b, solutions);
    ASSERT_GE(count, 1) << "trial " << trial;
    ASSERT_LE(count, 10);
    double best = 1e9;
    for (int s = 0; s < count; ++s) {
      const cv::Matx33d e(solutions[s].data());
      // Every solution satisfies the five constraints and is an essential matrix.
      for (int k = 0; k < 5; ++k)
        EXPECT_NEAR((cv::Vec3d(b[k][0], b[k][1], 1).t() * e * cv::Vec3d(a[k][0], a[k][1], 1))(0), 0,
                    1e-9);
      EXPECT_NEAR(cv::determinant(e), 0, 1e-9);
      best = std::min({best, cv::norm(e - truth), cv::norm(e + truth)});
    }
    EXPECT_LT(best, 1e-8) << "trial " << trial << ", " << count << " solutions";
  }
}

TEST(CameraMotionEstimator, RecoversRotationTranslationAndRelativeScale) {
  using namespace camera_motion;
  const ScannerGeometry g = distorted_geometry();
  cv::RNG rng(11);
  const std::vector<cv::Point3d> points = scene_points(180, rng);
  // Three camera poses: the second pair's translation is 1.6 times the first's.
  const Pose p0{};
  const Pose p1{rotation(0.8, -1.5, 0.4), cv::Vec3d(-0.06, 0.01, 0.02)};
  const Pose p2{rotation(1.5, -2.6, 0.9), cv::Vec3d(-0.155, 0.03, 0.035)};
  const Pose m01 = relative(p0, p1), m12 = relative(p1, p2);
  const double true_scale = cv::norm(m12.t) / cv::norm(m01.t);
  std::vector<cv::Point2f> f0 = project(points, p0, g, 0.3, rng);
  std::vector<cv::Point2f> f1 = project(points, p1, g, 0.3, rng);
  std::vector<cv::Point2f> f2 = project(points, p2, g, 0.3, rng);
  // 20 % of the tracks go wrong: anywhere in the image.
  std::vector<cv::Point2f> f1_seen = f1, f2_seen = f2;
  for (std::size_t i = 0; i < points.size(); i += 5) {
    f1_seen[i] = {static_cast<float>(rng.uniform(0.0, 1279.0)),
                  static_cast<float>(rng.uniform(0.0, 1023.0))};
    f2_seen[i + 2] = {static_cast<float>(rng.uniform(0.0, 1279.0)),
                      static_cast<float>(rng.uniform(0.0, 1023.0))};
  }

  MotionOptions options;
  CameraMotionEstimator estimator(options);
  estimator.reset(g, 256);
  const CameraMotion first = estimator.estimate(pair_tracks(f0, f1_seen), {});
  ASSERT_TRUE(first.valid);
  EXPECT_TRUE(std::isnan(first.relative_scale)) << "no previous pair";
  const double r01 = angle_between(rotation_of(first), m01.r);
  const double t01 = angle_between(translation_of(first), m01.t);
  EXPECT_NEAR(cv::norm(translation_of(first)), 1.0, 1e-9);
  // Where the points to follow are in the next frame: the same 3-D points (the estimator gives
  // back the current positions of its inlier tracks).
  std::vector<std::array<float, 2>> followed;
  for (const std::array<float, 2>& p : estimator.to_follow()) {
    std::size_t i = 0;
    while (i < f1_seen.size() && !(f1_seen[i].x == p[0] && f1_seen[i].y == p[1]))
      ++i;
    ASSERT_LT(i, f1_seen.size());
    followed.push_back({f2[i].x, f2[i].y});
  }
  EXPECT_EQ(followed.size(), static_cast<std::size_t>(options.scale_tracks));
  // One followed point is lost.
  followed[3] = {NAN, NAN};
  const CameraMotion second = estimator.estimate(pair_tracks(f1, f2_seen), followed);
  ASSERT_TRUE(second.valid);
  const double r12 = angle_between(rotation_of(second), m12.r);
  const double t12 = angle_between(translation_of(second), m12.t);
  std::printf("pair 0-1: %d inliers of %zu, R error %.4f deg, t error %.3f deg\n", first.inliers,
              points.size(), r01, t01);
  std::printf(
      "pair 1-2: %d inliers, R error %.4f deg, t error %.3f deg, relative scale %.4f "
      "(true %.4f)\n",
      second.inliers, r12, t12, second.relative_scale, true_scale);
  EXPECT_LT(r01, 0.05);
  EXPECT_LT(r12, 0.05);
  EXPECT_LT(t01, 1.5);
  EXPECT_LT(t12, 1.5);
  EXPECT_GE(first.inliers, 130);
  EXPECT_LE(first.inliers, 150) << "the outliers are not inliers";
  EXPECT_NEAR(second.relative_scale, true_scale, 0.03 * true_scale);
  // The inlier flags mark the tracks that went wrong as outliers.
  const auto flags = estimator.inliers();
  ASSERT_EQ(flags.size(), points.size());
  for (std::size_t i = 2; i < points.size(); i += 5)
    EXPECT_EQ(flags[i], 0) << i;
}

TEST(CameraMotionEstimator, PureRotationAndTooFewPointsAreInvalid) {
  using namespace camera_motion;
  const ScannerGeometry g = distorted_geometry();
  cv::RNG rng(5);
  const std::vector<cv::Point3d> points = scene_points(150, rng);
  CameraMotionEstimator estimator;
  estimator.reset(g, 256);
  const std::vector<cv::Point2f> f0 = project(points, Pose{}, g, 0.3, rng);
  // Rotation only: the translation's direction is not in the images.
  const std::vector<cv::Point2f> rotated =
      project(points, {rotation(1.0, -2.0, 0.5), {}}, g, 0.3, rng);
  const CameraMotion rotation_only = estimator.estimate(pair_tracks(f0, rotated), {});
  EXPECT_FALSE(rotation_only.valid);
  EXPECT_TRUE(estimator.to_follow().empty());
  // Still (no motion at all).
  EXPECT_FALSE(estimator.estimate(pair_tracks(f0, project(points, Pose{}, g, 0.3, rng)), {}).valid);
  // A translation of 2 mm at 1.2 - 3 m: under a pixel of parallax.
  EXPECT_FALSE(estimator
                   .estimate(pair_tracks(f0, project(points, {cv::Matx33d::eye(), {0.002, 0, 0}}, g,
                                                     0.3, rng)),
                             {})
                   .valid);
  // Four tracks: fewer than the five-point needs.
  const std::vector<cv::Point2f> moved =
      project(points, {rotation(0.5, 0, 0), {0.1, 0, 0}}, g, 0.3, rng);
  std::vector<FeatureTrack> tracks = pair_tracks(f0, moved);
  tracks.resize(4);
  EXPECT_FALSE(estimator.estimate(tracks, {}).valid);
  EXPECT_EQ(estimator.inliers().size(), 4u);
  // Unrelated points: no motion explains them.
  std::vector<cv::Point2f> random_points = f0;
  for (cv::Point2f& p : random_points)
    p = {static_cast<float>(rng.uniform(0.0, 1279.0)),
         static_cast<float>(rng.uniform(0.0, 1023.0))};
  const CameraMotion unrelated = estimator.estimate(pair_tracks(f0, random_points), {});
  EXPECT_FALSE(unrelated.valid);
  EXPECT_LT(unrelated.inliers, 12);
  // And the real motion with all of them is found again.
  EXPECT_TRUE(estimator.estimate(pair_tracks(f0, moved), {}).valid);
}

TEST(CameraMotionEstimator, EstimateDoesNotAllocate) {
  using namespace camera_motion;
  const ScannerGeometry g = distorted_geometry();
  cv::RNG rng(3);
  const std::vector<cv::Point3d> points = scene_points(192, rng);
  const std::vector<FeatureTrack> a =
      pair_tracks(project(points, Pose{}, g, 0.3, rng),
                  project(points, {rotation(0.5, 1, 0), {0.1, 0, 0.02}}, g, 0.3, rng));
  const std::vector<std::array<float, 2>> followed(64, std::array<float, 2>{600, 500});
  CameraMotionEstimator estimator;
  estimator.reset(g, 192);
  ASSERT_TRUE(testing::allocation_counter_works());
  testing::start_counting_allocations();
  const bool valid = estimator.estimate(a, {}).valid;
  const bool again = estimator.estimate(a, followed).valid;
  EXPECT_EQ(testing::stop_counting_allocations().count, 0);
  EXPECT_TRUE(valid);
  EXPECT_TRUE(again);
}

// The simulator's pier (bumps and piles of 5-30 cm, vehicle at 0.4 m/s, PTU scan, laser on)
// through MotionEstimator with the intrinsics: the camera motion against the simulator's poses.
TEST(MotionEstimator, CameraMotionOfSimulatedPierMatchesTheSimulator) {
  using namespace camera_motion;
  hal::SimSceneOptions o;
  o.calibration.camera.width = kWidth;
  o.calibration.camera.height = kHeight;
  o.frame_rate_hz = 30;
  o.distance_m = 1.2;
  o.tilt_y_deg = 8;
  o.sway_m = 0.01;
  o.sway_deg = 0.3;
  o.scan_rate_deg_s = 10;
  o.ambient = 150;
  o.texture_contrast = 0.6;
  o.laser_peak = 100;
  o.seed = 5;
  o.relief_height_m = 0.30;
  o.relief_min_height_m = 0.05;
  o.relief_max_slope = 0.9;
  o.vehicle_speed_m_s = 0.4;
  hal::SimScene scene(o);
  ScannerGeometry g;
  g.width = kWidth;
  g.height = kHeight;
  const hal::CameraIntrinsics& cam = o.calibration.camera;
  g.fx = cam.fx;
  g.fy = cam.fy;
  g.cx = cam.cx;
  g.cy = cam.cy;

  MotionEstimator estimator;
  estimator.reset(kWidth, kHeight, &g);
  cv::Mat frame(kHeight, kWidth, CV_8UC1);
  const auto pose = [&](std::uint64_t n) {
    const hal::SimCameraPose p = scene.camera_pose(n);
    const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> rotation = p.rotation;
    return Pose{cv::Matx33d(rotation.data()),
                cv::Vec3d(p.translation[0], p.translation[1], p.translation[2])};
  };
  constexpr int kFrames = 16;
  int valid = 0, scales = 0;
  long allocations = 0;
  ASSERT_TRUE(testing::allocation_counter_works());
  std::vector<double> rotation_errors, translation_errors, scale_errors;
  for (std::uint64_t n = 0; n < kFrames; ++n) {
    scene.render(n, true, {frame.ptr<std::uint8_t>(0), frame.total()});
    testing::start_counting_allocations();
    const MotionEstimate e = estimator.update(view_of(frame));
    allocations += testing::stop_counting_allocations().count;
    if (n == 0 || !e.camera.valid) {
      std::printf("frame %2d: camera motion invalid (%d inliers of %d tracks)\n",
                  static_cast<int>(n), e.camera.inliers, e.tracked);
      continue;
    }
    ++valid;
    const Pose truth = relative(pose(n - 1), pose(n));
    const double r_error = angle_between(rotation_of(e.camera), truth.r);
    const double t_error = angle_between(translation_of(e.camera), truth.t);
    rotation_errors.push_back(r_error);
    translation_errors.push_back(t_error);
    double true_scale = NAN;
    if (n >= 2) true_scale = cv::norm(truth.t) / cv::norm(relative(pose(n - 2), pose(n - 1)).t);
    if (std::isfinite(e.camera.relative_scale)) {
      ++scales;
      scale_errors.push_back(std::abs(e.camera.relative_scale / true_scale - 1));
    }
    std::printf(
        "frame %2d: %3d inliers of %3d tracks, R error %.3f deg (motion %.3f deg), t "
        "error %.2f deg, relative scale %.4f (true %.4f)\n",
        static_cast<int>(n), e.camera.inliers, e.tracked, r_error,
        angle_between(truth.r, cv::Matx33d::eye()), t_error, e.camera.relative_scale, true_scale);
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? NAN : v[v.size() / 2];
  };
  std::printf(
      "valid %d of %d pairs, median R error %.4f deg, median t error %.3f deg, %d relative "
      "scales, median error %.2f %%\n",
      valid, kFrames - 1, median(rotation_errors), median(translation_errors), scales,
      100 * median(scale_errors));
  EXPECT_GE(valid, kFrames - 3);
  EXPECT_LT(median(rotation_errors), 0.05);
  EXPECT_LT(median(translation_errors), 3.0);
  EXPECT_GE(scales, valid - 3);
  EXPECT_LT(median(scale_errors), 0.05);
  EXPECT_EQ(allocations, 0) << "update() with the camera motion allocates";

  // The PTU scan alone (the camera turns about its centre): nothing tells the translation's
  // direction, the camera motion is invalid while the homography is found.
  o.vehicle_speed_m_s = 0;
  o.sway_m = 0;
  hal::SimScene turning(o);
  estimator.reset(kWidth, kHeight, &g);
  int turning_valid = 0, homographies = 0;
  for (std::uint64_t n = 0; n < 6; ++n) {
    turning.render(n, true, {frame.ptr<std::uint8_t>(0), frame.total()});
    const MotionEstimate e = estimator.update(view_of(frame));
    turning_valid += e.camera.valid ? 1 : 0;
    homographies += e.valid ? 1 : 0;
  }
  EXPECT_EQ(turning_valid, 0);
  EXPECT_EQ(homographies, 5);
}

}  // namespace
}  // namespace laserline::pipeline
