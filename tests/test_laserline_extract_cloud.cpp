// laserline-extract's PLY point cloud: the points moved by the poses given, by frame number or
// by time (test_laserline_extract.cpp).
#include <gtest/gtest.h>

#include <unistd.h>
#include <laserline/calibration_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "laserline_extract_fixture.hpp"

namespace laserline {
namespace {

using namespace extract_test;

// Valid points per frame of a CSV, in frame order (the order of the PLY's points).
std::vector<std::size_t> valid_per_frame(const Csv& csv, long frames) {
  std::vector<std::size_t> counts(static_cast<std::size_t>(frames), 0);
  for (const auto& [frame, points] : csv.frames)
    for (const auto& p : points)
      counts.at(static_cast<std::size_t>(frame)) += p.valid == 1 ? 1 : 0;
  return counts;
}

// Expects `fused` to be `camera` moved by (R(q_k), t_k) for the points of frame k.
void expect_moved(const std::vector<std::array<float, 4>>& camera,
                  const std::vector<std::array<float, 4>>& fused,
                  const std::vector<std::size_t>& per_frame,
                  const std::vector<cv::Matx33d>& rotations,
                  const std::vector<cv::Vec3d>& translations) {
  ASSERT_EQ(fused.size(), camera.size());
  std::size_t i = 0;
  for (std::size_t k = 0; k < per_frame.size(); ++k) {
    for (std::size_t n = 0; n < per_frame[k]; ++n, ++i) {
      const cv::Vec3d expected =
          rotations[k] * cv::Vec3d(camera[i][0], camera[i][1], camera[i][2]) + translations[k];
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(fused[i][static_cast<std::size_t>(c)], expected[c], 1e-5)
            << "frame " << k << " point " << n;
      ASSERT_EQ(fused[i][3], camera[i][3]) << "the SNR goes with the point";
    }
  }
}

// Images carry no time: frame k takes pose row k.
TEST_F(LaserlineExtract, PlyPointCloudFusedWithPosesByFrameNumber) {
  hal::SimScene scene(options_);
  std::string inputs;
  for (int k = 0; k < 3; ++k) {
    ASSERT_TRUE(cv::imwrite(path("f" + std::to_string(k) + ".png"), render(scene, k)));
    inputs += " " + path("f" + std::to_string(k) + ".png");
  }
  RunResult r = extract("--ply " + path("camera.ply") + inputs);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const Csv csv = read_csv(path("points.csv"));
  const auto per_frame = valid_per_frame(csv, 3);
  const auto camera = read_ply(path("camera.ply"));
  ASSERT_EQ(camera.size(), per_frame[0] + per_frame[1] + per_frame[2]);
  EXPECT_NE(r.out.find(std::to_string(camera.size()) + " 3-D points in " + path("camera.ply") +
                       " (camera frame)"),
            std::string::npos)
      << r.out;
  // The same points as the CSV, in metres: Z is the scene's depth in that column.
  std::size_t i = 0;
  for (long k = 0; k < 3; ++k) {
    const hal::SimGroundTruth truth = truth_of(scene, static_cast<std::uint64_t>(k));
    for (const auto& p : csv.frames.at(k)) {
      EXPECT_NEAR(camera[i][2], truth.depth_m[static_cast<std::size_t>(p.u)], 0.02);
      EXPECT_NEAR(camera[i][3], p.snr_db, 0.01);
      ++i;
    }
  }

  const double h = std::sqrt(0.5);
  std::ofstream(path("poses.csv")) << "timestamp,x,y,z,qw,qx,qy,qz\n"
                                   << "0.0,0,0,0,1,0,0,0\n"
                                   << "0.1,1,2,3,0,0,0,1\n"  // 180 deg about z
                                   << "0.2,0,0,10," << h << "," << h << ",0,0\n";  // 90 about x
  r = extract("--ply " + path("world.ply") + " --poses " + path("poses.csv") + inputs);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  expect_moved(camera, read_ply(path("world.ply")), per_frame,
               {cv::Matx33d::eye(), cv::Matx33d(-1, 0, 0, 0, -1, 0, 0, 0, 1),
                cv::Matx33d(1, 0, 0, 0, 0, -1, 0, 1, 0)},
               {cv::Vec3d(0, 0, 0), cv::Vec3d(1, 2, 3), cv::Vec3d(0, 0, 10)});

  // Fewer rows than frames: the frame without a pose is named and left out of the cloud only.
  std::ofstream(path("short.csv")) << "0.0,0,0,0,1,0,0,0\n0.1,0,0,0,1,0,0,0\n";
  r = extract("--ply " + path("short.ply") + " --poses " + path("short.csv") + inputs);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: " + path("short.csv") + ": frame 2 (" + path("f2.png") +
                       ", no timestamp) has no pose: the log has 2 rows (frames without a time "
                       "take the row of their frame number); left out of " +
                       path("short.ply") + "\n"),
            std::string::npos)
      << r.out;
  EXPECT_EQ(read_ply(path("short.ply")).size(), per_frame[0] + per_frame[1]);
  EXPECT_EQ(read_csv(path("points.csv")).rows, csv.rows);

  // A bad pose file stops before any frame, naming file and line.
  std::ofstream(path("bad.csv")) << "0.0,0,0,0,1,0,0,0\n0.1,0,abc,0,1,0,0,0\n";
  r = extract("--ply " + path("bad.ply") + " --poses " + path("bad.csv") + inputs);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out,
            "laserline-extract: " + path("bad.csv") + ":2: y 'abc' is not a finite number\n");
  r = extract("--poses " + path("poses.csv") + inputs);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: --poses needs --ply (see --help)\n");
}

// LCM frames carry their exposure time: the pose is interpolated at it.
TEST_F(LaserlineExtract, PlyFromLcmLogInterpolatesPosesAtTheFrameTime) {
  hal::SimScene scene(options_);
  const std::string log_path = path("scan.lcmlog");
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    for (int k = 0; k < 3; ++k) {
      const cv::Mat image = render(scene, static_cast<std::uint64_t>(k));
      laserline::image_t m = image_message(image, k);  // utime 1.7e15 us + k * 33333 us
      m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
      m.row_stride = kWidth;
      m.data.assign(image.data, image.data + static_cast<std::size_t>(kWidth) * kHeight);
      m.size = static_cast<std::int32_t>(m.data.size());
      write_event(log, "LASERLINE_IMAGE", encode(m), m.utime);
    }
  }
  RunResult r = extract("--ply " + path("camera.ply") + " " + log_path);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const auto per_frame = valid_per_frame(read_csv(path("points.csv")), 3);
  const auto camera = read_ply(path("camera.ply"));

  // Moving along x at 1 m/s; the log ends between frames 1 and 2.
  std::ofstream(path("nav.csv")) << "1699999999.0,0,0,0,1,0,0,0\n"
                                 << "1700000000.05,1.05,0,0,1,0,0,0\n";
  r = extract("--ply " + path("world.ply") + " --poses " + path("nav.csv") + " " + log_path);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: " + path("nav.csv") + ": frame 2 (" + log_path +
                       " event 2 (LASERLINE_IMAGE)) at t=1700000000.066666 s is outside the pose "
                       "log's time span 1699999999.000000 .. 1700000000.050000 s; left out of " +
                       path("world.ply") + "\n"),
            std::string::npos)
      << r.out;
  auto two_frames = camera;
  two_frames.resize(per_frame[0] + per_frame[1]);
  expect_moved(two_frames, read_ply(path("world.ply")), {per_frame[0], per_frame[1]},
               {cv::Matx33d::eye(), cv::Matx33d::eye()},
               {cv::Vec3d(1.0, 0, 0), cv::Vec3d(1.033333, 0, 0)});
}

// Someone else's turntable scanner: step_num1.png ... step_num12.png. The folder is read in
// natural order (step_num2 before step_num10), each frame's CSV rows name its file, and pose row k
// moves the image that is frame k.
TEST_F(LaserlineExtract, FolderInNaturalOrderPairsPosesWithTheirFrames) {
  constexpr int kFrames = 12;
  fs::create_directories(dir_ / "steps");
  std::vector<hal::SimGroundTruth> truths;
  std::vector<std::string> files;
  // Each image from its own scene at its own distance: no two frames alike.
  for (int k = 0; k < kFrames; ++k) {
    options_.distance_m = 1.0 + 0.1 * k;
    hal::SimScene scene(options_);
    truths.push_back(truth_of(scene, 0));
    files.push_back(path("steps/step_num" + std::to_string(k + 1) + ".png"));
    ASSERT_TRUE(cv::imwrite(files.back(), render(scene, 0)));
  }
  {
    std::ofstream poses(path("poses.csv"));
    for (int k = 0; k < kFrames; ++k)
      poses << k << "," << 10 * k << ",0,0,1,0,0,0\n";
  }
  RunResult r =
      extract("--ply " + path("cloud.ply") + " --poses " + path("poses.csv") + " " + path("steps"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("note:"), std::string::npos) << r.out;
  const Csv csv = read_csv(path("points.csv"));
  ASSERT_EQ(csv.frames.size(), static_cast<std::size_t>(kFrames));
  for (long k = 0; k < kFrames; ++k) {
    EXPECT_EQ(csv.sources.at(k), files[static_cast<std::size_t>(k)]);
    expect_frame_matches(csv, k, truths[static_cast<std::size_t>(k)],
                         "step_num" + std::to_string(k + 1));
  }
  // Frame k's points moved by pose row k (x + 10 k), at image k's depths.
  const auto cloud = read_ply(path("cloud.ply"));
  ASSERT_EQ(cloud.size(), csv.rows);
  std::size_t i = 0;
  for (long k = 0; k < kFrames; ++k) {
    const auto& depth = truths[static_cast<std::size_t>(k)].depth_m;
    for (const auto& p : csv.frames.at(k)) {
      ASSERT_NEAR(cloud[i][0], 10.0 * static_cast<double>(k), 2.0) << "frame " << k;
      ASSERT_NEAR(cloud[i][2], depth[static_cast<std::size_t>(p.u)], 0.02)
          << "frame " << k << " column " << p.u;
      ++i;
    }
  }

  // The same files as a shell glob gives them (alphabetical): taken in the order given, and said.
  std::vector<std::string> globbed = files;
  std::sort(globbed.begin(), globbed.end());
  std::string arguments;
  for (const auto& f : globbed)
    arguments += " " + f;
  r = extract(arguments);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: note: the 12 image arguments from " + files[0] +
                       " on are not in natural order (step_num12.png before step_num2.png): "
                       "frames are numbered in the order given; give their folder to read them "
                       "in natural order\n"),
            std::string::npos)
      << r.out;
  const Csv given = read_csv(path("points.csv"));
  EXPECT_EQ(given.sources.at(1), files[9]);
  expect_frame_matches(given, 1, truths[9], "step_num10");
  // In natural order: nothing to say.
  arguments.clear();
  for (const auto& f : files)
    arguments += " " + f;
  r = extract(arguments);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("note:"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace laserline
