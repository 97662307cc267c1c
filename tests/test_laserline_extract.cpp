// laserline-extract run as the real executable on frames rendered by the simulated scanner and
// written as PNG files, folders, videos and LCM logs; its CSV is checked against the simulator's
// exact ground truth. Damaged inputs and refusals: test_laserline_extract_problems.cpp; options:
// _options.cpp; point clouds: _cloud.cpp (one binary).
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

TEST_F(LaserlineExtract, MonoPngFolderAndFilesInInputOrder) {
  hal::SimScene scene(options_);
  fs::create_directories(dir_ / "seq");
  // Written out of order: the folder is read sorted by name.
  for (int k : {2, 0, 1}) {
    ASSERT_TRUE(cv::imwrite(path("seq/img_" + std::to_string(k) + ".png"), render(scene, k)));
  }
  std::ofstream(path("seq/notes.txt")) << "not an image, ignored\n";
  RunResult r = extract(path("seq"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find('\r'), std::string::npos) << "no progress bar when not on a terminal";
  EXPECT_NE(r.out.find("3 frames from 1 inputs, 3 processed with maxvalue"), std::string::npos)
      << r.out;
  Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.header, "frame,source,u,v,x,y,snr_db,segment,valid");
  EXPECT_EQ(csv.frames.size(), 3u);
  expect_frames_match(csv, {{0, 0}, {1, 1}, {2, 2}}, scene);

  // Files on the command line: frame numbers follow the argument order.
  r = extract(path("seq/img_2.png") + " " + path("seq/img_0.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.size(), 2u);
  expect_frames_match(csv, {{0, 2}, {1, 0}}, scene);
}

// A laser beside the camera: the line runs down the image and every detector searches the rows.
// u is then the row and v the column, x and y the frame pixel; every row's point is the truth's.
TEST_F(LaserlineExtract, LaserBesideTheCameraSearchesRows) {
  options_.calibration.laser.side = hal::LaserSide::kRight;
  options_.tilt_x_deg = 8;
  options_.tilt_y_deg = 0;
  hal::SimScene scene(options_);
  ASSERT_EQ(scene.lines().line_step[1], 1.0) << "the simulator draws the line along rows";
  ASSERT_TRUE(cv::imwrite(path("beside.png"), render(scene, 0)));
  const std::string calib = write_calibration(
      "beside.yaml", "{baseline_m: 0.25, angle_deg: 80, sheet_width_m: 0.003, side: right}");
  const hal::SimGroundTruth truth = truth_of(scene, 0);
  std::size_t visible = 0;
  for (float position : truth.position)
    visible += std::isfinite(position) ? 1 : 0;
  ASSERT_GT(visible, static_cast<std::size_t>(kHeight * 0.9));
  for (const std::string detector : {"maxvalue", "fir"}) {
    const RunResult r = extract(path("beside.png"), detector, calib);
    EXPECT_EQ(r.exit_code, 0) << r.out;
    const Csv csv = read_csv(path("points.csv"));
    ASSERT_TRUE(csv.frames.count(0)) << r.out;
    std::size_t found = 0;
    for (const CsvPoint& p : csv.frames.at(0)) {
      ASSERT_GE(p.u, 0);
      ASSERT_LT(p.u, kHeight);
      EXPECT_DOUBLE_EQ(p.y, p.u) << detector;   // the row
      EXPECT_NEAR(p.x, p.v, 1e-3) << detector;  // the column
      const float position = truth.position[static_cast<std::size_t>(p.u)];
      ASSERT_TRUE(std::isfinite(position)) << detector << ": a point in row " << p.u;
      EXPECT_NEAR(p.x, position, kTolerancePx) << detector << ", row " << p.u;
      ++found;
    }
    EXPECT_GE(found, visible * 99 / 100) << detector;
  }
}

// The laser is green: only the green channel counts. Red and blue carry a bright stripe
// elsewhere that wins under any grey conversion (0.299 R + 0.587 G + 0.114 B) but is absent
// from green.
TEST_F(LaserlineExtract, ColourPngUsesTheGreenChannel) {
  options_.laser_peak = 120;
  options_.texture_contrast = 0.2;
  hal::SimScene scene(options_);
  const cv::Mat green = render(scene, 0);
  const hal::SimGroundTruth truth = truth_of(scene, 0);
  cv::Mat red_blue = cv::Mat::zeros(kHeight, kWidth, CV_8UC1);
  red_blue.rowRange(200, 205).setTo(255);
  for (int u = 0; u < kWidth; ++u)
    ASSERT_LT(truth.position[u], 180.0f) << "the stripe must be away from the laser";
  cv::Mat bgr;
  cv::merge(std::vector<cv::Mat>{red_blue, green, red_blue}, bgr);
  ASSERT_TRUE(cv::imwrite(path("colour.png"), bgr));
  const RunResult r = extract(path("colour.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}}, scene);
}

// Real green-laser images clip: the core saturates white in every channel, only the fringes
// stay green. Also as a 16-bit PNG, which must give exactly the 8-bit result.
TEST_F(LaserlineExtract, SaturatedColourAndSixteenBit) {
  options_.laser_peak = 2500;  // core far above 255: a flat top several pixels wide
  options_.noise_sigma = 1.0;
  hal::SimScene scene(options_);
  const cv::Mat green = render(scene, 0);
  int clipped_columns = 0;
  for (int u = 0; u < kWidth; ++u) {
    int run = 0;
    for (int v = 0; v < kHeight; ++v)
      run += green.at<std::uint8_t>(v, u) == 255 ? 1 : 0;
    clipped_columns += run >= 3 ? 1 : 0;
  }
  ASSERT_GT(clipped_columns, kWidth * 9 / 10) << "the scene must clip";
  cv::Mat white_core;
  cv::compare(green, 255, white_core, cv::CMP_EQ);  // 255 where clipped, 0 elsewhere
  cv::Mat bgr;
  cv::merge(std::vector<cv::Mat>{white_core, green, white_core}, bgr);
  ASSERT_TRUE(cv::imwrite(path("clipped.png"), bgr));
  cv::Mat sixteen;
  green.convertTo(sixteen, CV_16U, 257.0);
  ASSERT_TRUE(cv::imwrite(path("clipped16.png"), sixteen));
  ASSERT_TRUE(cv::imwrite(path("clipped8.png"), green));

  RunResult r = extract(path("clipped.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}}, scene);

  r = extract(path("clipped8.png") + " " + path("clipped16.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  const Csv csv = read_csv(path("points.csv"));
  ASSERT_EQ(csv.frames.size(), 2u);
  ASSERT_EQ(csv.frames.at(0).size(), csv.frames.at(1).size());
  for (std::size_t i = 0; i < csv.frames.at(0).size(); ++i) {
    EXPECT_EQ(csv.frames.at(0)[i].u, csv.frames.at(1)[i].u);
    EXPECT_EQ(csv.frames.at(0)[i].v, csv.frames.at(1)[i].v) << "column " << csv.frames.at(0)[i].u;
  }
}

// A 12-bit camera's frames in 16-bit PNG files (samples 0..4095 in the low bits): read on their
// own range, as the same frames in 8 bit are; a frame that needs more bits raises them, and
// --bit-depth fixes them.
TEST_F(LaserlineExtract, SixteenBitFilesOfATwelveBitCamera) {
  hal::SimScene scene(options_);
  fs::create_directories(dir_ / "eight");
  fs::create_directories(dir_ / "twelve");
  for (int k = 0; k < 3; ++k) {
    const cv::Mat frame = render(scene, k);
    ASSERT_TRUE(cv::imwrite(path("eight/" + std::to_string(k) + ".png"), frame));
    cv::Mat twelve;
    frame.convertTo(twelve, CV_16U, 4095.0 / 255.0);
    ASSERT_TRUE(cv::imwrite(path("twelve/" + std::to_string(k) + ".png"), twelve));
  }
  RunResult r = extract(path("eight"), "fir");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const Csv eight = read_csv(path("points.csv"));
  r = extract(path("twelve"), "fir");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("0.png: 16-bit samples of at most 12 bits: read as 12-bit"),
            std::string::npos)
      << r.out;
  const Csv twelve = read_csv(path("points.csv"));
  ASSERT_EQ(twelve.frames.size(), 3u);
  expect_frames_match(twelve, {{0, 0}, {1, 1}, {2, 2}}, scene);
  for (long frame = 0; frame < 3; ++frame) {
    ASSERT_EQ(twelve.frames.at(frame).size(), eight.frames.at(frame).size()) << frame;
    for (std::size_t i = 0; i < eight.frames.at(frame).size(); ++i)
      EXPECT_EQ(twelve.frames.at(frame)[i].v, eight.frames.at(frame)[i].v) << frame << " " << i;
  }

  // Told 16 bits, the tool takes them so (16 times darker) and says nothing of its own choice.
  r = extract("--bit-depth 16 " + path("twelve"), "fir");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("read as 12-bit"), std::string::npos) << r.out;

  // A first frame of 10 bits, then 12-bit ones: from the second frame on, 12 bits.
  fs::create_directories(dir_ / "mixed");
  for (int k = 0; k < 3; ++k) {
    cv::Mat sixteen;
    render(scene, k).convertTo(sixteen, CV_16U, (k == 0 ? 1023.0 : 4095.0) / 255.0);
    ASSERT_TRUE(cv::imwrite(path("mixed/" + std::to_string(k) + ".png"), sixteen));
  }
  r = extract(path("mixed"), "fir");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("0.png: 16-bit samples of at most 10 bits: read as 10-bit"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("1.png: samples beyond the 10 bits of the frames before: read as 12-bit "
                       "from here on"),
            std::string::npos)
      << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}, {1, 1}, {2, 2}}, scene);

  r = extract("--bit-depth 7 " + path("twelve"), "fir");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("--bit-depth '7': the bits of the camera's samples in 16-bit frames, a "
                       "whole number from 8 to 16"),
            std::string::npos)
      << r.out;
}

// Lossless FFV1 in Matroska: the decoded frames are the rendered ones, so the 0.5 px bound
// holds as for PNG. Debian's OpenCV writes it through FFmpeg.
TEST_F(LaserlineExtract, Video) {
  hal::SimScene scene(options_);
  const std::string video = path("scan.mkv");
  {
    cv::VideoWriter writer(video, cv::CAP_FFMPEG, cv::VideoWriter::fourcc('F', 'F', 'V', '1'), 30,
                           cv::Size(kWidth, kHeight), false);
    ASSERT_TRUE(writer.isOpened()) << "this OpenCV cannot write FFV1 video";
    for (int k = 0; k < 4; ++k)
      writer.write(render(scene, k));
  }
  const RunResult r = extract(video);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.size(), 4u);
  expect_frames_match(csv, {{0, 0}, {1, 1}, {2, 2}, {3, 3}}, scene);
}

// Motion JPEG, the codec most cameras and recorders write: lossy, so the points are checked
// within the same bound on a scene whose texture JPEG keeps well.
TEST_F(LaserlineExtract, MotionJpegVideo) {
  hal::SimScene scene(options_);
  const std::string video = path("scan.avi");
  ASSERT_TRUE(write_motion_jpeg(video, scene, 2)) << "this OpenCV cannot write MJPG video";
  const RunResult r = extract(video);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}, {1, 1}}, scene);
}

// issue 16: a log says which calibration made it. Without --calib the log's calibration_t is
// used (and said so); a --calib that is another calibration is refused before anything is
// written, unless --override-log-calibration; profiles naming another calibration are a mismatch
// too.
TEST_F(LaserlineExtract, LcmLogCarriesItsCalibration) {
  hal::SimScene scene(options_);
  const hal::Calibration recorded = hal::load_calibration_file(calib_);
  const std::uint64_t id = hal::calibration_id(recorded);
  const std::string dive = path("dive.lcmlog");
  write_dive(dive, scene, recorded, id);
  const std::string csv = path("points.csv");
  const std::string common =
      std::string(LASERLINE_EXTRACT_PATH) + " --detector maxvalue --output " + csv + " ";

  RunResult r = run_command(common + dive);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: calibration " + hal::calibration_id_text(id) +
                       " from the log " + dive + "\n"),
            std::string::npos)
      << r.out;
  expect_frames_match(read_csv(csv), {{0, 0}, {1, 1}}, scene);

  // The same calibration given: taken without a word.
  r = run_command(common + "--calib " + calib_ + " " + dive);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("from the log"), std::string::npos) << r.out;

  // Another calibration (the sheet 1 mm further away): refused, one line naming both ids.
  const std::string other = write_calibration(
      "other.yaml",
      "{baseline_m: " + std::to_string(options_.calibration.laser.baseline_m + 0.001) +
          ", angle_deg: " + std::to_string(options_.calibration.laser.angle_deg) + "}");
  const std::uint64_t other_id = hal::calibration_id(hal::load_calibration_file(other));
  fs::remove(csv);
  r = run_command(common + "--calib " + other + " " + dive);
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_EQ(r.out, "laserline-extract: --calib " + other + " is calibration " +
                       hal::calibration_id_text(other_id) + ", but " + dive +
                       " was recorded with calibration " + hal::calibration_id_text(id) + " (" +
                       dive +
                       " event 0 (LASERLINE_CALIBRATION)); leave out --calib to use the log's, or "
                       "add --override-log-calibration\n");
  EXPECT_FALSE(fs::exists(csv)) << "refused before any output";
  r = run_command(common + "--calib " + other + " --override-log-calibration " + dive);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(fs::exists(csv));

  // No calibration_t, profiles naming another calibration than --calib: refused the same way.
  const std::string profiles_only = path("profiles_only.lcmlog");
  write_dive(profiles_only, scene, std::nullopt, other_id);
  r = run_command(common + "--calib " + calib_ + " " + profiles_only);
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find(" was recorded with calibration " + hal::calibration_id_text(other_id) +
                       " (" + profiles_only + " event 1 (LASERLINE_PROFILE))"),
            std::string::npos)
      << r.out;
  // ... and without --calib there is nothing to extract them with.
  r = run_command(common + profiles_only);
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_EQ(r.out, "laserline-extract: --calib is required: the profiles of " + profiles_only +
                       " event 1 (LASERLINE_PROFILE) name calibration " +
                       hal::calibration_id_text(other_id) +
                       ", but no laserline.calibration_t in the log carries it (see --help)\n");
  // An image without a log: --calib is required.
  r = run_command(common + path("none.png"));
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_EQ(r.out,
            "laserline-extract: --calib is required: no input is an LCM log that carries a "
            "laserline.calibration_t (see --help)\n");

  // A log whose calibration_t is one calibration and whose profiles name another (two
  // recordings joined): without --calib, its frames are not extracted with either.
  const std::string mixed = path("mixed.lcmlog");
  write_dive(mixed, scene, recorded, other_id);
  r = run_command(common + mixed);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find(
                "laserline-extract: " + mixed + ": event 2 (LASERLINE_PROFILE) names calibration " +
                hal::calibration_id_text(other_id) + ", not " + hal::calibration_id_text(id) +
                " of " + mixed + "'s calibration_t in use; skipped"),
            std::string::npos)
      << r.out;
}

// A log as laserlined and lcm-logger record it: image_t frames (8-bit with row padding,
// 16-bit little and big endian, PNG-compressed), profile_t messages between them, and one
// image_t whose payload is cut short.
TEST_F(LaserlineExtract, LcmLogOfImageMessages) {
  hal::SimScene scene(options_);
  const std::string log_path = path("dive.lcmlog");
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    std::int64_t utime = 1'700'000'000'000'000;
    // Frame 0: 8-bit grey, rows padded to 384 bytes.
    {
      const cv::Mat image = render(scene, 0);
      laserline::image_t m = image_message(image, 0);
      m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
      m.row_stride = 384;
      m.data.assign(static_cast<std::size_t>(m.row_stride) * kHeight, 0xAB);
      for (int v = 0; v < kHeight; ++v)
        std::memcpy(m.data.data() + static_cast<std::size_t>(v) * m.row_stride, image.ptr(v),
                    kWidth);
      m.size = static_cast<std::int32_t>(m.data.size());
      write_event(log, "LASERLINE_IMAGE", encode(m), utime += 33'333);
    }
    // Profiles on their own channel: not frames, but they give the laser state of the image
    // with the same sequence number (image_t has none); frame 2 was exposed with the laser off.
    for (int k : {0, 2}) {
      laserline::profile_t p;
      p.sequence = k;
      p.calibration_id = static_cast<std::int64_t>(
          hal::calibration_id(hal::load_calibration_file(calib_)));  // the one given
      p.laser_on = k != 2;
      p.detector = "maxvalue";
      p.num_points = 0;
      write_event(log, "LASERLINE_PROFILE", encode(p), utime += 10);
    }
    // Frames 1 and 2: 16-bit little and big endian; frame 2 with the laser off, as its profile
    // says.
    for (int k : {1, 2}) {
      const cv::Mat image = render(scene, k, k != 2);
      laserline::image_t m = image_message(image, k);
      m.pixelformat = k == 1
                          ? static_cast<std::int32_t>(laserline::image_t::PIXEL_FORMAT_LE_GRAY16)
                          : static_cast<std::int32_t>(laserline::image_t::PIXEL_FORMAT_BE_GRAY16);
      m.row_stride = kWidth * 2;
      for (int v = 0; v < kHeight; ++v) {
        for (int u = 0; u < kWidth; ++u) {
          const std::uint16_t value =
              static_cast<std::uint16_t>(image.at<std::uint8_t>(v, u) * 257);
          const std::uint8_t lo = value & 0xFF, hi = value >> 8;
          m.data.push_back(k == 1 ? lo : hi);
          m.data.push_back(k == 1 ? hi : lo);
        }
      }
      m.size = static_cast<std::int32_t>(m.data.size());
      write_event(log, "LASERLINE_IMAGE", encode(m), utime += 33'333);
    }
    // Frame 3: cut short (the hash says image_t, the payload is truncated).
    {
      laserline::image_t m = image_message(render(scene, 3), 3);
      m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
      m.row_stride = kWidth;
      m.data.assign(static_cast<std::size_t>(kWidth) * kHeight, 0);
      m.size = static_cast<std::int32_t>(m.data.size());
      std::vector<std::uint8_t> data = encode(m);
      data.resize(100);
      write_event(log, "LASERLINE_IMAGE", data, utime += 33'333);
    }
    // Frame 4: PNG-compressed.
    {
      const cv::Mat image = render(scene, 4);
      laserline::image_t m = image_message(image, 4);
      m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
      m.row_stride = kWidth;
      m.compression = laserline::image_t::COMPRESSION_PNG;
      ASSERT_TRUE(cv::imencode(".png", image, m.data));
      m.size = static_cast<std::int32_t>(m.data.size());
      write_event(log, "LASERLINE_IMAGE", encode(m), utime += 33'333);
    }
  }
  // The recording was cut short in the middle of a last event.
  const auto complete = fs::file_size(log_path);
  std::ofstream(log_path, std::ios::binary | std::ios::app)
      .write("\xED\xA1\xDA\x01\x00\x00\x00\x00\x00\x00\x00\x09", 12);
  ASSERT_EQ(fs::file_size(log_path), complete + 12);

  const RunResult r = extract(log_path);
  EXPECT_EQ(r.exit_code, 1) << "the truncated frame is a failure: " << r.out;
  EXPECT_NE(r.out.find(log_path + ": bytes " + std::to_string(complete) + ".." +
                       std::to_string(complete + 11) +
                       " are not a complete event (recording cut short?); ignored\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find(log_path + " event 5 (LASERLINE_IMAGE): not a valid laserline.image_t: "
                                  "size at byte 59: 81920 elements (81920 bytes) but 37 bytes "
                                  "remain; "
                                  "skipped"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("laserline-extract: 1 of the processed frames were exposed with the laser "
                       "off (1 from the log's profiles): no points taken from them\n"),
            std::string::npos)
      << r.out;
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.count(3), 0u);
  EXPECT_EQ(csv.frames.count(2), 0u) << "a laser-off frame gives no points";
  expect_frames_match(csv, {{0, 0}, {1, 1}, {4, 4}}, scene);
  EXPECT_EQ(csv.sources.at(0), log_path + " event 0 (LASERLINE_IMAGE)");
  EXPECT_EQ(csv.sources.at(4), log_path + " event 6 (LASERLINE_IMAGE)");
}

}  // namespace
}  // namespace laserline
