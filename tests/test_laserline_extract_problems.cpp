// laserline-extract on damaged logs, images and videos, missing inputs, bad arguments and
// calibrations: each named in one line, the good frames kept (test_laserline_extract.cpp).
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
#include <iterator>
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

// A damaged record in the middle of a log (LCM's own reader stopped there and lost the rest): the
// frames after it are extracted, the damage is reported with its byte offsets, exit status 1. A
// hostile image_t (row_stride -1: a segfault in memcpy before) is refused in one line.
TEST_F(LaserlineExtract, LcmLogDamagedInTheMiddleIsReadThrough) {
  hal::SimScene scene(options_);
  const std::string log_path = path("damaged.lcmlog");
  auto frame = [&](int k) {
    const cv::Mat image = render(scene, k);
    laserline::image_t m = image_message(image, k);
    m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
    m.row_stride = kWidth;
    m.data.assign(image.data, image.data + image.total());
    m.size = static_cast<std::int32_t>(m.data.size());
    return m;
  };
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    write_event(log, "LASERLINE_IMAGE", encode(frame(0)), 1);
    laserline::image_t hostile = frame(1);
    hostile.row_stride = -1;
    write_event(log, "LASERLINE_IMAGE", encode(hostile), 2);
  }
  const auto damage_at = fs::file_size(log_path);
  std::ofstream(log_path, std::ios::binary | std::ios::app)
      .write("\xED\xA1\xDA\x01 not an event", 17);
  {
    const std::string tail_path = path("tail.lcmlog");
    {
      lcm::LogFile log(tail_path, "w");
      write_event(log, "LASERLINE_IMAGE", encode(frame(2)), 3);
      write_event(log, "LASERLINE_IMAGE", encode(frame(3)), 4);
    }
    std::ifstream tail(tail_path, std::ios::binary);
    std::ofstream(log_path, std::ios::binary | std::ios::app) << tail.rdbuf();
  }
  const RunResult r = extract(log_path);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find(log_path + ": bytes " + std::to_string(damage_at) + ".." +
                       std::to_string(damage_at + 16) +
                       " are damaged (1 records); skipped, reading resumes at event 0"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find(log_path + " event 1 (LASERLINE_IMAGE): row_stride -1 and 81920 bytes do "
                                  "not hold a 320x256 frame; skipped"),
            std::string::npos)
      << r.out;
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.count(1), 0u);
  expect_frames_match(csv, {{0, 0}, {2, 2}, {3, 3}}, scene);
}

TEST_F(LaserlineExtract, CorruptImageBetweenGoodOnesKeepsTheOthers) {
  hal::SimScene scene(options_);
  fs::create_directories(dir_ / "seq");
  ASSERT_TRUE(cv::imwrite(path("seq/a0.png"), render(scene, 0)));
  ASSERT_TRUE(cv::imwrite(path("seq/a2.png"), render(scene, 2)));
  std::vector<std::uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", render(scene, 1), png));
  png.resize(png.size() / 3);  // truncated: the signature is right, the data is not
  std::ofstream(path("seq/a1.png"), std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));

  const RunResult r = extract(path("seq"));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  const std::string a1 = "laserline-extract: " + path("seq/a1.png") + ": ";
  EXPECT_TRUE(is_with_number(line_starting(r.out, a1),
                             a1 + "damaged image (cut short: chunk IDAT at byte ",
                             " runs past the end); skipped"))
      << r.out;
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.count(1), 0u);
  expect_frames_match(csv, {{0, 0}, {2, 2}}, scene);
}

// An image cut short or damaged decodes without an error in OpenCV (a JPEG cut in half gave 60 of
// 320 columns off by up to 219 px, exit 0): each is named and skipped, the run ends with status
// 1, and the good frames around them are all written.
TEST_F(LaserlineExtract, DamagedImagesAreNamedAndSkippedTheGoodOnesKept) {
  hal::SimScene scene(options_);
  fs::create_directories(dir_ / "seq");
  auto encoded = [&](const char* ext, std::uint64_t sequence) {
    std::vector<std::uint8_t> bytes;
    EXPECT_TRUE(cv::imencode(ext, render(scene, sequence), bytes, {cv::IMWRITE_JPEG_QUALITY, 100}));
    return bytes;
  };
  write_bytes(path("seq/f0.png"), encoded(".png", 0));
  std::vector<std::uint8_t> jpeg = encoded(".jpg", 1);
  jpeg.resize(jpeg.size() / 2);
  write_bytes(path("seq/f1.jpg"), jpeg);
  write_bytes(path("seq/f2.jpg"), encoded(".jpg", 2));
  std::vector<std::uint8_t> png = encoded(".png", 3);
  png.resize(png.size() - 12);  // the IEND chunk only
  write_bytes(path("seq/f3.png"), png);
  png = encoded(".png", 4);
  png[png.size() / 2] ^= 0x40;  // one bit inside the image data
  write_bytes(path("seq/f4.png"), png);
  // Zeros after the end-of-image marker (some cameras pad files) are not damage; an
  // end-of-image marker inside a metadata segment (as in an EXIF thumbnail) is not the end.
  jpeg = encoded(".jpg", 5);
  jpeg.insert(jpeg.end(), 64, 0);
  write_bytes(path("seq/f5.jpg"), jpeg);
  jpeg = encoded(".jpg", 6);
  const std::vector<std::uint8_t> app1 = {0xFF, 0xE1, 0x00, 0x08, 'E', 'x', 0xFF, 0xD8, 0xFF, 0xD9};
  jpeg.insert(jpeg.begin() + 2, app1.begin(), app1.end());
  jpeg.resize(jpeg.size() * 3 / 5);
  write_bytes(path("seq/f6.jpg"), jpeg);
  write_bytes(path("seq/f7.png"), encoded(".png", 7));

  const RunResult r = extract(path("seq"));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  for (const char* line :
       {"f1.jpg: damaged image (cut short in the image data: no end-of-image marker (FF D9)); "
        "skipped",
        "f3.png: damaged image (cut short: no IEND chunk); skipped",
        "f6.jpg: damaged image (cut short in the image data: no end-of-image marker (FF D9)); "
        "skipped"}) {
    EXPECT_NE(r.out.find("laserline-extract: " + path("seq/") + line + "\n"), std::string::npos)
        << line << "\n"
        << r.out;
  }
  const std::string f4 = "laserline-extract: " + path("seq/f4.png") + ": ";
  EXPECT_TRUE(is_with_number(line_starting(r.out, f4),
                             f4 + "damaged image (damaged: chunk IDAT at byte ",
                             " fails its CRC); skipped"))
      << r.out;
  EXPECT_NE(r.out.find("8 frames from 1 inputs, 4 processed with maxvalue"), std::string::npos)
      << r.out;
  const Csv csv = read_csv(path("points.csv"));
  for (long damaged : {1, 3, 4, 6})
    EXPECT_EQ(csv.frames.count(damaged), 0u) << "frame " << damaged;
  expect_frames_match(csv, {{0, 0}, {7, 7}}, scene);
  // JPEG at quality 100: within the tolerance of the lossless frames on this scene.
  expect_frames_match(csv, {{2, 2}, {5, 5}}, scene);
}

// A video cut short decodes its first frames and then ends as if complete (16 of 30 frames,
// exit 0, no word): the container's frame count says what is missing. The frames that decoded
// are all written.
TEST_F(LaserlineExtract, VideoCutShortIsReportedItsFramesKept) {
  hal::SimScene scene(options_);
  const std::string video = path("scan.avi");
  ASSERT_TRUE(write_motion_jpeg(video, scene, 30)) << "this OpenCV cannot write MJPG video";
  std::vector<std::uint8_t> bytes = read_bytes(video);
  bytes.resize(bytes.size() / 2);
  write_bytes(path("cut.avi"), bytes);
  cv::VideoCapture capture(path("cut.avi"), cv::CAP_FFMPEG);
  ASSERT_TRUE(capture.isOpened());
  ASSERT_EQ(capture.get(cv::CAP_PROP_FRAME_COUNT), 30.0) << "the header's count survives the cut";
  int decodable = 0;
  for (cv::Mat frame; capture.read(frame);)
    ++decodable;
  std::printf("the cut video decodes %d of its 30 frames\n", decodable);
  ASSERT_GT(decodable, 0);
  ASSERT_LT(decodable, 30);

  const RunResult r = extract(path("cut.avi"));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  const std::string n = std::to_string(decodable);
  EXPECT_NE(r.out.find("laserline-extract: " + path("cut.avi") + ": only " + n +
                       " of the 30 frames its container announces could be decoded (cut short or "
                       "damaged?); those " +
                       n + " were processed\n"),
            std::string::npos)
      << r.out;
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.size(), static_cast<std::size_t>(decodable));
  expect_frames_match(csv, {{0, 0}, {decodable / 2, static_cast<std::uint64_t>(decodable / 2)}},
                      scene);

  // The whole video: every frame, status 0.
  const RunResult whole = extract(video);
  EXPECT_EQ(whole.exit_code, 0) << whole.out;
  EXPECT_EQ(read_csv(path("points.csv")).frames.size(), 30u);
}

TEST_F(LaserlineExtract, MissingAndWrongSizeInputsAreNamedAndSkipped) {
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("good.png"), render(scene, 0)));
  ASSERT_TRUE(cv::imwrite(path("small.png"), cv::Mat(120, 160, CV_8UC1, cv::Scalar(10))));
  std::ofstream(path("garbage.avi")) << std::string(5000, 'x');
  const RunResult r = extract(path("nothere.png") + " " + path("small.png") + " " +
                              path("garbage.avi") + " " + path("good.png"));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: " + path("nothere.png") +
                       ": no such file or folder; skipped\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(
      r.out.find("laserline-extract: " + path("small.png") +
                 ": image is 160x120 but the calibration " + calib_ + " is for 320x256; skipped\n"),
      std::string::npos)
      << r.out;
  EXPECT_NE(
      r.out.find("laserline-extract: " + path("garbage.avi") + ": not a readable video; skipped\n"),
      std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("3 problems"), std::string::npos) << r.out;
  // The missing path and the unreadable video take no frame number (it is not known to be a frame);
  // the wrong-size image does.
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.size(), 1u);
  expect_frames_match(csv, {{1, 0}}, scene);
}

// A video of the wrong size is one line, not one per frame; many bad frames in one input are
// counted beyond the first ten lines.
TEST_F(LaserlineExtract, RepeatedProblemsDoNotFloodTheTerminal) {
  {
    cv::VideoWriter writer(path("small.mkv"), cv::CAP_FFMPEG,
                           cv::VideoWriter::fourcc('F', 'F', 'V', '1'), 30, cv::Size(160, 128),
                           false);
    ASSERT_TRUE(writer.isOpened());
    for (int k = 0; k < 5; ++k)
      writer.write(cv::Mat(128, 160, CV_8UC1, cv::Scalar(k)));
  }
  fs::create_directories(dir_ / "small");
  for (int k = 0; k < 12; ++k) {
    ASSERT_TRUE(cv::imwrite(path("small/s" + std::to_string(k + 10) + ".png"),
                            cv::Mat(20, 20, CV_8UC1, cv::Scalar(0))));
  }
  const RunResult r = extract(path("small.mkv") + " " + path("small"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("laserline-extract: " + path("small.mkv") +
                       ": video is 160x128 but the calibration is for 320x256; skipped\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find(path("small/s19.png") + ": image is 20x20"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(path("small/s20.png")), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: " + path("small") +
                       ": further problems in this input are counted, not shown\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("12 frames from 2 inputs, 0 processed with maxvalue, 0 points written "
                       "(0 valid) to " +
                       path("points.csv") + ", 13 problems (see above)"),
            std::string::npos)
      << r.out;
  std::size_t lines = 0;
  for (char c : r.out)
    lines += c == '\n';
  EXPECT_EQ(lines, 13u) << r.out;  // video, 10 images, "further problems", summary
}

TEST_F(LaserlineExtract, BadArgumentsAndConfiguration) {
  RunResult r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: unknown option '--frobnicate' (see --help)\n");
  r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --calib " + calib_ +
                  " --detector maxvalue --output " + path("p.csv"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: no INPUT given (see --help)\n");
  r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --calib");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: --calib: missing value (see --help)\n");
  r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out.rfind("usage: laserline-extract", 0), 0u) << r.out;
  EXPECT_NE(r.out.find("maxvalue"), std::string::npos) << "lists the detectors: " << r.out;

  r = extract("x.png", "nosuchdetector");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out.rfind("laserline-extract: --detector: unknown detector 'nosuchdetector' (one "
                        "of: maxvalue",
                        0),
            0u)
      << r.out;

  std::ofstream(path("bad.yaml")) << "detector:\n  maxvalue: {threshold: 0}\n";
  r = extract("--config " + path("bad.yaml") + " x.png");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: " + path("bad.yaml") +
                       ":2: detector.maxvalue.threshold: must be between 1 and 255, got 0\n");

  std::ofstream(path("file")) << "a file, not a folder\n";
  r = extract("--overlay-dir " + path("file/overlays") + " x.png");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(
      r.out.rfind(
          "laserline-extract: --overlay-dir " + path("file/overlays") + ": cannot be created: ", 0),
      0u)
      << r.out;

  std::ofstream(path("badcalib.yaml")) << "camera: {fx: -1}\n";
  r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --calib " + path("badcalib.yaml") +
                  " --detector maxvalue --output " + path("p.csv") + " x.png");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: " + path("badcalib.yaml") +
                       ":1: camera.fx: must be between 1 and 1e+06, got -1\n");

  // A directory, a device or an empty file is no calibration or configuration: before, --calib
  // on a directory extracted with the default camera.
  std::ofstream(path("empty.yaml")) << "";
  for (const auto& [args, line] : std::vector<std::pair<std::string, std::string>>{
           {"--calib " + dir_.string(),
            dir_.string() +
                ": is a directory, not a file: give a configuration or calibration file"},
           {"--calib " + path("empty.yaml"),
            path("empty.yaml") + ": has no keys (empty, or only comments)"},
           {"--calib " + calib_ + " --config /dev/null",
            "/dev/null: is a character device, not a file: give a configuration or calibration "
            "file"}}) {
    r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " " + args +
                    " --detector maxvalue --output " + path("p.csv") + " x.png");
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(r.out, "laserline-extract: " + line + "\n");
  }
}

// A full disk: the first CSV write that fails is named and ends the run at once with status 1
// (no summary of a run that did not finish).
TEST_F(LaserlineExtract, WriteFailureEndsTheRunWithStatusOne) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f0.png"), render(scene, 0)));
  ASSERT_TRUE(cv::imwrite(path("f1.png"), render(scene, 1)));
  const RunResult r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --calib " + calib_ +
                                  " --detector maxvalue --output /dev/full " + path("f0.png") +
                                  " " + path("f1.png"));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: /dev/full: write failed: No space left on device\n"),
            std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("frames from"), std::string::npos) << r.out;
}

// --output - writes the CSV to standard output (for a pipe), the same bytes as to a file; the
// messages stay on standard error. A full disk there is said as for a file.
TEST_F(LaserlineExtract, CsvToStandardOutput) {
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f0.png"), render(scene, 0)));
  ASSERT_TRUE(cv::imwrite(path("f1.png"), render(scene, 1)));
  const std::string inputs = " " + path("f0.png") + " " + path("f1.png");
  RunResult r = extract(inputs);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string command =
      std::string(LASERLINE_EXTRACT_PATH) + " --calib " + calib_ + " --detector maxvalue";
  r = run_command("(" + command + " --output -" + inputs + " > " + path("piped.csv") + ")");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(
      r.out.find("points written (" + std::to_string(kWidth * 2) + " valid) to standard output\n"),
      std::string::npos)
      << r.out;
  auto bytes = [](const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  EXPECT_EQ(bytes(path("piped.csv")), bytes(path("points.csv")));
  EXPECT_EQ(bytes(path("piped.csv")).rfind("frame,source,u,v,x,y,snr_db,segment,valid\n", 0), 0u);

  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  r = run_command("(" + command + " --output -" + inputs + " > /dev/full)");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(
      r.out.find("laserline-extract: standard output: write failed: No space left on device\n"),
      std::string::npos)
      << r.out;
}

// A calibration the camera cannot work with stops the run before any frame, naming the file; one
// that leaves most points without a 3-D point says so at the end.
TEST_F(LaserlineExtract, CalibrationErrorsAreOneLine) {
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f.png"), render(scene, 0)));
  const std::string behind = write_calibration("behind.yaml", "{plane: [0, 0.5, 0.866, 0.25]}");
  RunResult r = extract(path("f.png"), "maxvalue", behind);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: " + behind +
                       ": laser.plane: the sheet [0, 0.5, 0.866, 0.25] lies behind the camera at "
                       "every pixel of the 320x256 image, so no point can be triangulated (with e "
                       "of the other sign it would be in front: a sign flipped?)\n");
  EXPECT_FALSE(fs::exists(path("points.csv"))) << "stopped before any output";

  std::ofstream(path("near.yaml"))
      << "detector:\n  frontend: {min_depth_m: 0.1, max_depth_m: 0.3}\n";
  r = extract("--config " + path("near.yaml") + " " + path("f.png"), "fir");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-extract: " + calib_ +
                       ": laser: the 320x256 image sees the laser sheet at depths 0.462 m to "
                       "infinity, none of them within the depth range searched, 0.1 to 0.3 m "
                       "(detector.frontend.min_depth_m and max_depth_m of " +
                       path("near.yaml") + "): check the calibration or the range\n");
  r = extract("--config " + path("near.yaml") + " " + path("f.png"), "maxvalue");
  EXPECT_EQ(r.exit_code, 0) << "maxvalue does not search by depth: " << r.out;

  // e of the wrong sign: the sheet is still seen at the bottom of the image, so the run goes on,
  // but the line is where its rays miss the sheet: no point reaches the cloud.
  const std::string flipped =
      write_calibration("flipped.yaml", "{plane: [0, 0.985, -0.174, -0.246]}");
  r = extract("--ply " + path("cloud.ply") + " " + path("f.png"), "maxvalue", flipped);
  EXPECT_EQ(r.exit_code, 3) << r.out;
  const std::size_t accepted = read_csv(path("points.csv")).rows;
  ASSERT_GT(accepted, 300u);
  EXPECT_NE(
      r.out.find("laserline-extract: " + std::to_string(accepted) + " of " +
                 std::to_string(accepted) +
                 " accepted points (100.0%) have no 3-D point and are left out of " +
                 path("cloud.ply") + ": their rays do not meet the laser sheet of " + flipped +
                 " in front of the camera (is its plane's sign or the laser's "
                 "side wrong?)\n"),
      std::string::npos)
      << r.out;
  EXPECT_EQ(read_ply(path("cloud.ply")).size(), 0u);
  // The right sign: every point in the cloud, no such line.
  const std::string right = write_calibration("right.yaml", "{plane: [0, 0.985, -0.174, 0.246]}");
  r = extract("--ply " + path("cloud.ply") + " " + path("f.png"), "maxvalue", right);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("no 3-D point"), std::string::npos) << r.out;
  EXPECT_EQ(read_ply(path("cloud.ply")).size(), read_csv(path("points.csv")).rows);
}

}  // namespace
}  // namespace laserline
