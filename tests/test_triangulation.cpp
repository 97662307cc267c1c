// Laser points to metres: against the simulator's exact 3-D truth, against analytically distorted
// points (cv::projectPoints), and the point cloud and pose log files of laserline-extract.
#include "pipeline/triangulation.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "allocation_counter.hpp"
#include "daemon/config.hpp"
#include "tools/evaluation.hpp"
#include "tools/point_cloud.hpp"

namespace laserline {
namespace {

using pipeline::ProfilePoint;
using pipeline::ScannerGeometry;
using pipeline::Triangulator;

// The simulated scanner at the 1.5 m on the clean scenario, through the real detector
// path (make_detector decorates it with triangulation); truth xyz from the true row and depth.
TEST(Triangulation, CleanSceneAtOneAndAHalfMetresIsWithinOneMillimetreRms) {
  tools::Scenario scenario;
  for (const auto& s : tools::standard_scenarios())
    if (s.name == "clean") scenario = s;
  ASSERT_EQ(scenario.name, "clean");
  scenario.scene.distance_m = 1.5;
  scenario.frames = 6;
  const ScannerGeometry geometry = daemon::scanner_geometry(scenario.scene.calibration);
  const Triangulator triangulator(geometry);

  for (const char* detector : {"fir", "background"}) {
    long matched = 0, truth_columns = 0, unmatched = 0, not_triangulated = 0;
    double sum_sq = 0, sum_sq_truth_row = 0, max_error = 0, sum_z = 0;
    tools::evaluate(scenario, detector, {}, 2.0, [&](const tools::ScoredFrame& f) {
      for (float row : f.truth->position)
        truth_columns += std::isfinite(row) ? 1 : 0;
      for (const ProfilePoint& p : f.profile->points()) {
        if (!p.valid) continue;
        const auto u = static_cast<std::size_t>(p.u);
        const double row = f.truth->position[u], z = f.truth->depth_m[u];
        if (!std::isfinite(row) || std::abs(p.v - row) > 2.0) {
          ++unmatched;
          continue;
        }
        if (!std::isfinite(p.xyz[2])) {
          ++not_triangulated;
          continue;
        }
        const double truth[3] = {(p.u - geometry.cx) / geometry.fx * z,
                                 (row - geometry.cy) / geometry.fy * z, z};
        double e2 = 0;
        for (int i = 0; i < 3; ++i)
          e2 += (p.xyz[i] - truth[i]) * (p.xyz[i] - truth[i]);
        sum_sq += e2;
        max_error = std::max(max_error, std::sqrt(e2));
        sum_z += z;
        ++matched;
        // The truth row itself lands on the truth point: the simulator's sheet is the plane the
        // triangulation uses.
        Eigen::Vector3d at_truth_row;
        ASSERT_TRUE(triangulator.point(p.u, row, at_truth_row));
        double t2 = 0;
        for (int i = 0; i < 3; ++i)
          t2 += (at_truth_row[i] - truth[i]) * (at_truth_row[i] - truth[i]);
        sum_sq_truth_row += t2;
      }
    });
    ASSERT_GT(matched, 0);
    const double rms_mm = 1e3 * std::sqrt(sum_sq / static_cast<double>(matched));
    std::printf(
        "%-10s %ld points, mean depth %.3f m: 3-D error rms %.3f mm, max %.3f mm; truth row "
        "-> truth point rms %.2e mm; %ld valid points off the line, %ld not triangulated\n",
        detector, matched, sum_z / static_cast<double>(matched), rms_mm, 1e3 * max_error,
        1e3 * std::sqrt(sum_sq_truth_row / static_cast<double>(matched)), unmatched,
        not_triangulated);
    EXPECT_LE(rms_mm, 1.0) << detector;
    EXPECT_NEAR(sum_z / static_cast<double>(matched), 1.5, 0.1);
    EXPECT_GE(static_cast<double>(matched), 0.95 * static_cast<double>(truth_columns)) << detector;
    EXPECT_EQ(not_triangulated, 0) << detector;
    EXPECT_LT(std::sqrt(sum_sq_truth_row / static_cast<double>(matched)), 1e-6);
    RecordProperty(std::string(detector) + "_rms_mm", std::to_string(rms_mm));
  }
}

// A strongly distorting lens: points of the laser sheet projected by OpenCV's own model come
// back to where they were. The sheet is a calibrated plane, turned about the optical axis too.
TEST(Triangulation, RemovesLensDistortionAsOpenCvAppliesIt) {
  ScannerGeometry g;
  g.distortion = {-0.28, 0.12, 0.0012, -0.0008, -0.03};
  g.laser_plane = {0.052, 0.9825, -0.1789, 0.22};
  const Triangulator triangulator(g);
  const double a = g.laser_plane[0], b = g.laser_plane[1], c = g.laser_plane[2],
               e = g.laser_plane[3];
  // Points of the sheet: X across the field, Z over the working range; Y from the plane.
  std::vector<cv::Point3d> truth;
  for (double z = 0.6; z <= 2.5; z += 0.1) {
    for (double x_over_z = -0.4; x_over_z <= 0.4; x_over_z += 0.02) {
      const double x = x_over_z * z;
      truth.emplace_back(x, -(a * x + c * z + e) / b, z);
    }
  }
  const cv::Matx33d k(g.fx, 0, g.cx, 0, g.fy, g.cy, 0, 0, 1);
  std::vector<cv::Point2d> pixels;
  cv::projectPoints(truth, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k,
                    std::vector<double>(g.distortion.begin(), g.distortion.end()), pixels);
  double worst = 0, worst_shift_px = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    Eigen::Vector3d xyz;
    ASSERT_TRUE(triangulator.point(pixels[i].x, pixels[i].y, xyz)) << i;
    worst = std::max({worst, std::abs(xyz[0] - truth[i].x), std::abs(xyz[1] - truth[i].y),
                      std::abs(xyz[2] - truth[i].z)});
    // How far the lens moved the point: the test means something only if that is large.
    const double ux = g.fx * truth[i].x / truth[i].z + g.cx;
    const double uy = g.fy * truth[i].y / truth[i].z + g.cy;
    worst_shift_px = std::max(worst_shift_px, std::hypot(pixels[i].x - ux, pixels[i].y - uy));
  }
  std::printf("%zu points, distortion up to %.1f px, worst 3-D error %.2e m\n", truth.size(),
              worst_shift_px, worst);
  EXPECT_GT(worst_shift_px, 30.0);
  EXPECT_LT(worst, 1e-6);
}

TEST(Triangulation, OnlyValidPointsOnTheSheetInFrontGetCoordinatesWithoutAllocating) {
  ScannerGeometry g;  // sheet Y = -0.25 + tan(10 deg) Z: seen only above row cy + fy tan(10 deg)
  const Triangulator triangulator(g);
  pipeline::Profile profile(4);
  profile.add({100, 400.0f, 10.0f, -1, true});   // on the sheet, Z about 1 m
  profile.add({100, 400.0f, 10.0f, -1, false});  // rejected by the detector
  profile.add({100, 900.0f, 10.0f, -1, true});   // the ray meets the sheet behind the camera
  testing::start_counting_allocations();
  triangulator.fill(profile);
  const testing::Allocations allocations = testing::stop_counting_allocations();
  EXPECT_EQ(allocations.count, 0);
  ASSERT_TRUE(testing::allocation_counter_works());
  const auto& p = profile.points();
  const double y = (400.0 - g.cy) / g.fy;
  const double z = 0.25 / (std::tan(10.0 * std::numbers::pi / 180.0) - y);
  EXPECT_NEAR(p[0].xyz[2], z, 1e-6);
  EXPECT_NEAR(p[0].xyz[1], y * z, 1e-6);
  EXPECT_NEAR(p[0].xyz[0], (100 - g.cx) / g.fx * z, 1e-6);
  for (int i : {1, 2})
    for (float coordinate : p[static_cast<std::size_t>(i)].xyz)
      EXPECT_TRUE(std::isnan(coordinate)) << "point " << i;
}

class PointCloudFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("laserline_point_cloud_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    if (!HasFailure()) std::filesystem::remove_all(dir_);
  }
  std::string write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  // The one-line error loading `text` as a pose log gives.
  std::string pose_error(const std::string& text) {
    const std::string path = write("bad.csv", text);
    try {
      tools::PoseLog::load(path);
    } catch (const tools::PointCloudError& e) {
      const std::string message = e.what();
      EXPECT_EQ(message.find('\n'), std::string::npos);
      EXPECT_EQ(message.rfind(path, 0), 0u) << message;
      return message.substr(path.size());
    }
    ADD_FAILURE() << "no error for: " << text;
    return "";
  }
  std::filesystem::path dir_;
};

TEST_F(PointCloudFiles, PlyHeaderCountAndValuesReadBack) {
  const std::string path = (dir_ / "cloud.ply").string();
  {
    tools::PlyWriter ply(path, "test cloud");
    ply.add({1.0, -2.5, 3.25}, 12.5f);
    ASSERT_TRUE(ply.commit());
    ply.add({0.125, 0.0, 1e-3}, 3.0f);
    ply.add({-4.0, 5.0, 6.0}, 30.0f);
  }  // the destructor commits the rest
  std::ifstream in(path, std::ios::binary);
  std::string line, header;
  std::vector<std::string> lines;
  while (std::getline(in, line) && line != "end_header")
    lines.push_back(line);
  ASSERT_EQ(lines.size(), 8u);
  EXPECT_EQ(lines[0], "ply");
  EXPECT_EQ(lines[1], "format binary_little_endian 1.0");
  EXPECT_EQ(lines[2], "comment test cloud");
  EXPECT_EQ(lines[3].rfind("element vertex 3 ", 0), 0u) << lines[3];
  EXPECT_EQ(lines[4], "property float x");
  EXPECT_EQ(lines[7], "property float scalar_snr");
  std::vector<unsigned char> body((std::istreambuf_iterator<char>(in)), {});
  ASSERT_EQ(body.size(), 3u * 4u * 4u);
  auto value = [&](std::size_t i) {  // little-endian float i
    std::uint32_t bits = 0;
    for (int k = 3; k >= 0; --k)
      bits = (bits << 8) | body[4 * i + static_cast<std::size_t>(k)];
    float f = 0;
    std::memcpy(&f, &bits, 4);
    return f;
  };
  const float expected[] = {1.0f,  -2.5f, 3.25f, 12.5f, 0.125f, 0.0f,
                            1e-3f, 3.0f,  -4.0f, 5.0f,  6.0f,   30.0f};
  for (std::size_t i = 0; i < 12; ++i)
    EXPECT_EQ(value(i), expected[i]) << i;
}

TEST_F(PointCloudFiles, PosesMovePointsAndInterpolate) {
  // 90 deg about z at t = 10 s, 180 deg about z at t = 12 s; position moves 2 m along x.
  const double h = std::sqrt(0.5);
  const std::string path =
      write("poses.csv", "timestamp,x,y,z,qw,qx,qy,qz\n10.0,1,2,3," + std::to_string(h) + ",0,0," +
                             std::to_string(h) + "\n\n12.0, 3, 2, 3, 0, 0, 0, 1\n");
  const tools::PoseLog log = tools::PoseLog::load(path);
  ASSERT_EQ(log.size(), 2u);
  tools::Pose pose;
  ASSERT_TRUE(log.at_index(0, pose));
  auto p = pose.apply({1, 0, 0});  // x rotated onto y, then moved
  EXPECT_NEAR(p[0], 1.0, 1e-6);
  EXPECT_NEAR(p[1], 3.0, 1e-6);
  EXPECT_NEAR(p[2], 3.0, 1e-6);
  ASSERT_TRUE(log.at_time(11.0, pose));  // halfway: 135 deg, position (2, 2, 3)
  p = pose.apply({1, 0, 0});
  EXPECT_NEAR(p[0], 2.0 + std::cos(0.75 * std::numbers::pi), 1e-6);
  EXPECT_NEAR(p[1], 2.0 + std::sin(0.75 * std::numbers::pi), 1e-6);
  EXPECT_NEAR(p[2], 3.0, 1e-6);
  EXPECT_TRUE(log.at_time(12.0, pose));
  EXPECT_FALSE(log.at_time(9.999, pose));
  EXPECT_FALSE(log.at_time(12.001, pose));
  EXPECT_FALSE(log.at_index(2, pose));
}

TEST_F(PointCloudFiles, BadPoseLogsGiveOneLineErrorsNamingTheLine) {
  EXPECT_EQ(pose_error("t,x,y,z,qw,qx,qy,qz\n1,0,0,0,1,0,0,0\n2,0,0,0,1,0,0\n"),
            ":3: expected 8 fields timestamp,x,y,z,qw,qx,qy,qz, found 7");
  EXPECT_EQ(pose_error("1,0,0,0,1,0,0,0\n2,0,zero,0,1,0,0,0\n"),
            ":2: y 'zero' is not a finite number");
  EXPECT_EQ(pose_error("1,0,0,0,1,0,0,0\n2,0,0,0,0.5,0,0,0\n"),
            ":2: quaternion qw,qx,qy,qz has norm 0.500000, not 1");
  EXPECT_EQ(pose_error("1,0,0,0,1,0,0,0\n\n1,0,0,0,1,0,0,0\n"),
            ":3: timestamp 1.000000 is not after the previous row's 1.000000 (line 1)");
  EXPECT_EQ(pose_error("timestamp,x,y,z,qw,qx,qy,qz\n"),
            ": no pose rows (expected timestamp,x,y,z,qw,qx,qy,qz)");
  EXPECT_EQ(pose_error("1,0,0,0,1,0,0,nan\n"), ":1: qz 'nan' is not a finite number");
  try {
    tools::PoseLog::load((dir_ / "missing.csv").string());
    ADD_FAILURE() << "no error for a missing file";
  } catch (const tools::PointCloudError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.csv: cannot be read: No such file"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace laserline
