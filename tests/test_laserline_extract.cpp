// laserline-extract run as the real executable on frames rendered by the simulated scanner and
// written as PNG files, folders, videos and LCM logs; its CSV is checked against the simulator's
// exact ground truth.
// Over 600 lines: one program, its inputs, outputs and refusals, on one fixture.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>
#include <laserline/calibration_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <lcm/lcm-cpp.hpp>
#include "run_command.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/sim/sim_scene.hpp"

namespace laserline {
namespace {

namespace fs = std::filesystem;

using RunResult = laserline::test_support::CommandResult;
using laserline::test_support::run_command;

struct CsvPoint {
  int u = 0;
  double v = 0;
  double x = 0, y = 0;  // the frame pixel
  double snr_db = 0;
  int segment = 0;
  int valid = 0;
};

struct Csv {
  std::string header;
  std::map<long, std::vector<CsvPoint>> frames;
  std::map<long, std::string> sources;  // frame -> its source column
  std::size_t rows = 0;
};

// The fields of one CSV line, RFC 4180 quoting undone.
std::vector<std::string> csv_fields(const std::string& line) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
      fields.back() += '"';
      ++i;
    } else if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  return fields;
}

Csv read_csv(const std::string& path) {
  Csv csv;
  std::ifstream in(path);
  std::getline(in, csv.header);
  std::string line;
  while (std::getline(in, line)) {
    const std::vector<std::string> f = csv_fields(line);
    EXPECT_EQ(f.size(), 9u) << "bad CSV line: " << line;
    if (f.size() != 9u) continue;
    const long frame = std::stol(f[0]);
    CsvPoint p;
    p.u = std::stoi(f[2]);
    p.v = std::stod(f[3]);
    p.x = std::stod(f[4]);
    p.y = std::stod(f[5]);
    p.snr_db = std::stod(f[6]);
    p.segment = std::stoi(f[7]);
    p.valid = std::stoi(f[8]);
    csv.frames[frame].push_back(p);
    const auto [source, added] = csv.sources.emplace(frame, f[1]);
    EXPECT_EQ(source->second, f[1]) << "one source per frame: " << line;
    ++csv.rows;
  }
  return csv;
}

// How one frame's points compare with the simulator's truth.
struct Accuracy {
  std::size_t truth_columns = 0;  // columns where the laser is visible
  std::size_t found = 0;          // of those, columns with a valid point
  std::size_t outside = 0;        // valid points farther than the tolerance (or where no laser)
  double max_error = 0;
  double sum_sq = 0;
  double rms() const { return found > 0 ? std::sqrt(sum_sq / static_cast<double>(found)) : NAN; }
  double recall() const {
    return truth_columns > 0 ? static_cast<double>(found) / static_cast<double>(truth_columns) : 0;
  }
};

Accuracy compare(const std::vector<CsvPoint>& points, const hal::SimGroundTruth& truth,
                 double tolerance_px) {
  Accuracy a;
  for (float row : truth.position)
    a.truth_columns += std::isfinite(row) ? 1 : 0;
  for (const auto& p : points) {
    if (p.valid != 1) continue;
    if (p.u < 0 || p.u >= static_cast<int>(truth.position.size()) ||
        !std::isfinite(truth.position[p.u])) {
      ++a.outside;
      continue;
    }
    const double error = std::abs(p.v - truth.position[p.u]);
    if (error > tolerance_px) {
      ++a.outside;
      continue;
    }
    ++a.found;
    a.max_error = std::max(a.max_error, error);
    a.sum_sq += error * error;
  }
  return a;
}

std::size_t lines(const std::string& text) {
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

constexpr int kWidth = 320;
constexpr int kHeight = 256;
constexpr double kTolerancePx = 0.5;

hal::SimSceneOptions scene_options() {
  hal::SimSceneOptions o;
  o.calibration.camera.width = kWidth;
  o.calibration.camera.height = kHeight;
  o.calibration.camera.fx = o.calibration.camera.fy = 350;
  o.calibration.camera.cx = 159.5;
  o.calibration.camera.cy = 127.5;
  o.seed = 7;
  o.tilt_y_deg = 8;
  o.texture_contrast = 0.3;
  return o;
}

cv::Mat render(hal::SimScene& scene, std::uint64_t sequence, bool laser_on = true) {
  cv::Mat image(kHeight, kWidth, CV_8UC1);
  scene.render(sequence, laser_on,
               std::span<std::uint8_t>(image.data, static_cast<std::size_t>(kWidth) * kHeight));
  return image;
}

// Frames 0 .. frames-1 of `scene` as a Motion JPEG video at the best quality; false when this
// OpenCV cannot write one.
bool write_motion_jpeg(const std::string& video, hal::SimScene& scene, int frames) {
  cv::VideoWriter writer(video, cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30,
                         cv::Size(kWidth, kHeight), false);
  if (!writer.isOpened()) return false;
  writer.set(cv::VIDEOWRITER_PROP_QUALITY, 100);
  for (int k = 0; k < frames; ++k)
    writer.write(render(scene, static_cast<std::uint64_t>(k)));
  return true;
}

hal::SimGroundTruth truth_of(const hal::SimScene& scene, std::uint64_t sequence) {
  hal::SimGroundTruth truth;
  scene.ground_truth(sequence, true, truth);
  return truth;
}

class LaserlineExtract : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("laserline_extract_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // The calibration as OpenCV's calibration sample writes it, laser section added, all
    // written by cv::FileStorage: the tool reads that layout as is.
    calib_ = path("calib.yml");
    cv::FileStorage fs(calib_, cv::FileStorage::WRITE);
    const auto& c = options_.calibration.camera;
    fs << "image_width" << c.width << "image_height" << c.height;
    fs << "camera_matrix"
       << cv::Mat((cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1));
    fs << "distortion_coefficients" << cv::Mat::zeros(5, 1, CV_64F);
    const auto& l = options_.calibration.laser;
    fs << "laser"
       << "{"
       << "baseline_m" << l.baseline_m << "angle_deg" << l.angle_deg << "sheet_width_m"
       << l.sheet_width_m << "}";
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  RunResult extract(const std::string& args, const std::string& detector = "maxvalue",
                    const std::string& calib = "") {
    return run_command(std::string(LASERLINE_EXTRACT_PATH) + " --calib " +
                       (calib.empty() ? calib_ : calib) + " --detector " + detector + " --output " +
                       path("points.csv") + " " + args);
  }

  // Every frame in `expected` (CSV frame -> scene sequence) is found within the tolerance.
  void expect_frames_match(const Csv& csv, const std::map<long, std::uint64_t>& expected,
                           const hal::SimScene& scene, double tolerance_px = kTolerancePx) {
    for (const auto& [frame, sequence] : expected) {
      expect_frame_matches(csv, frame, truth_of(scene, sequence),
                           "scene frame " + std::to_string(sequence), tolerance_px);
    }
  }

  void expect_frame_matches(const Csv& csv, long frame, const hal::SimGroundTruth& truth,
                            const std::string& label, double tolerance_px = kTolerancePx) {
    ASSERT_TRUE(csv.frames.count(frame)) << "frame " << frame << " missing from the CSV";
    const Accuracy a = compare(csv.frames.at(frame), truth, tolerance_px);
    std::printf(
        "frame %ld (%s): %zu/%zu columns within %.2f px, rms %.3f px, max %.3f px, %zu outside\n",
        frame, label.c_str(), a.found, a.truth_columns, tolerance_px, a.rms(), a.max_error,
        a.outside);
    EXPECT_GT(a.truth_columns, static_cast<std::size_t>(kWidth * 0.9));
    EXPECT_GE(a.recall(), 0.99) << "frame " << frame;
    EXPECT_EQ(a.outside, 0u) << "frame " << frame;
  }

  // A calibration in laserline's own layout: the test camera, the given laser section.
  std::string write_calibration(const std::string& name, const std::string& laser) {
    const auto& c = options_.calibration.camera;
    std::ofstream(path(name)) << "camera: {width: " << c.width << ", height: " << c.height
                              << ", fx: " << c.fx << ", fy: " << c.fy << ", cx: " << c.cx
                              << ", cy: " << c.cy << "}\nlaser: " << laser << "\n";
    return path(name);
  }

  hal::SimSceneOptions options_ = scene_options();
  fs::path dir_;
  std::string calib_;
};

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

laserline::image_t image_message(const cv::Mat& image, std::int64_t sequence) {
  laserline::image_t m;
  m.utime = 1'700'000'000'000'000 + sequence * 33'333;
  m.sequence = sequence;
  m.width = image.cols;
  m.height = image.rows;
  m.compression = laserline::image_t::COMPRESSION_NONE;
  return m;
}

void write_event(lcm::LogFile& log, const std::string& channel,
                 const std::vector<std::uint8_t>& data, std::int64_t utime) {
  lcm::LogEvent event;
  event.timestamp = utime;
  event.channel = channel;
  event.datalen = static_cast<std::int32_t>(data.size());
  event.data = const_cast<std::uint8_t*>(data.data());
  ASSERT_EQ(log.writeEvent(&event), 0);
}

template <typename Message>
std::vector<std::uint8_t> encode(const Message& m) {
  std::vector<std::uint8_t> data(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(data.data(), 0, static_cast<int>(data.size())), static_cast<int>(data.size()));
  return data;
}

// What laserlined publishes on LASERLINE_CALIBRATION, written here field by field.
laserline::calibration_t calibration_message(const hal::Calibration& c) {
  laserline::calibration_t m{};
  m.utime = 1'700'000'000'000'000;
  m.calibration_id = static_cast<std::int64_t>(hal::calibration_id(c));
  m.width = c.camera.width;
  m.height = c.camera.height;
  m.fx = c.camera.fx;
  m.fy = c.camera.fy;
  m.cx = c.camera.cx;
  m.cy = c.camera.cy;
  std::copy(c.camera.distortion.begin(), c.camera.distortion.end(), m.distortion);
  const std::array<double, 4> plane = c.laser.plane_coefficients();
  std::copy(plane.begin(), plane.end(), m.laser_plane);
  m.sheet_width_m = c.laser.sheet_width_m;
  return m;
}

// A log of frames 0 and 1 as a daemon of `calibration` records it: its calibration_t first
// (unless left out), then each frame's image_t and a profile naming the calibration.
void write_dive(const std::string& log_path, hal::SimScene& scene,
                const std::optional<hal::Calibration>& published, std::uint64_t profile_id) {
  lcm::LogFile log(log_path, "w");
  ASSERT_TRUE(log.good());
  std::int64_t utime = 1'700'000'000'000'000;
  if (published) {
    write_event(log, "LASERLINE_CALIBRATION", encode(calibration_message(*published)), utime);
  }
  for (int k : {0, 1}) {
    const cv::Mat image = render(scene, k);
    laserline::image_t m = image_message(image, k);
    m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
    m.row_stride = kWidth;
    m.data.assign(image.data, image.data + image.total());
    m.size = static_cast<std::int32_t>(m.data.size());
    write_event(log, "LASERLINE_IMAGE", encode(m), utime += 33'333);
    laserline::profile_t p{};
    p.sequence = k;
    p.laser_on = true;
    p.detector = "maxvalue";
    p.calibration_id = static_cast<std::int64_t>(profile_id);
    write_event(log, "LASERLINE_PROFILE", encode(p), utime += 10);
  }
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

// Whether `line` is `before`, a whole number, then `after` (a byte offset that depends on how
// OpenCV splits its PNG data into chunks).
bool is_with_number(const std::string& line, const std::string& before, const std::string& after) {
  if (line.size() <= before.size() + after.size() || line.rfind(before, 0) != 0 ||
      line.compare(line.size() - after.size(), after.size(), after) != 0) {
    return false;
  }
  const std::string number = line.substr(before.size(), line.size() - before.size() - after.size());
  return number.find_first_not_of("0123456789") == std::string::npos;
}

// The line of `out` that begins with `start` ("" when none).
std::string line_starting(const std::string& out, const std::string& start) {
  const std::size_t at = out.find(start);
  return at == std::string::npos ? "" : out.substr(at, out.find('\n', at) - at);
}

// Bytes of a file, written or read whole.
void write_bytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}
std::vector<std::uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

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

TEST_F(LaserlineExtract, OverlaysAndAllCandidates) {
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f.png"), render(scene, 0)));
  RunResult r = extract("--overlay-dir " + path("overlays") + " " + path("f.png"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const Csv valid_only = read_csv(path("points.csv"));
  const cv::Mat overlay = cv::imread(path("overlays/frame_000000.png"), cv::IMREAD_COLOR);
  ASSERT_FALSE(overlay.empty()) << r.out;
  EXPECT_EQ(overlay.cols, kWidth);
  EXPECT_EQ(overlay.rows, kHeight);
  ASSERT_FALSE(valid_only.frames.at(0).empty());
  int green = 0;
  for (const auto& p : valid_only.frames.at(0)) {
    const auto px = overlay.at<cv::Vec3b>(static_cast<int>(std::lround(p.v)), p.u);
    green += px[1] > px[0] + 40 && px[1] > px[2] + 40 ? 1 : 0;
  }
  EXPECT_GT(green, static_cast<int>(valid_only.frames.at(0).size() * 9 / 10))
      << "accepted points are drawn green";

  r = extract("--all-candidates " + path("f.png"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const Csv all = read_csv(path("points.csv"));
  for (const auto& p : valid_only.frames.at(0))
    EXPECT_EQ(p.valid, 1) << "without --all-candidates only accepted points";
  std::size_t valid_in_all = 0;
  for (const auto& p : all.frames.at(0))
    valid_in_all += p.valid == 1 ? 1 : 0;
  EXPECT_EQ(valid_in_all, valid_only.frames.at(0).size());
  EXPECT_GE(all.frames.at(0).size(), valid_only.frames.at(0).size());
}

TEST_F(LaserlineExtract, ProgressBarOnlyOnATerminal) {
  if (std::system("script --version >/dev/null 2>&1") != 0) GTEST_SKIP() << "no script(1)";
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f.png"), render(scene, 0)));
  // script(1) gives the tool a terminal.
  const RunResult r = run_command("script -qec '" + std::string(LASERLINE_EXTRACT_PATH) +
                                  " --calib " + calib_ + " --detector maxvalue --output " +
                                  path("points.csv") + " " + path("f.png") + "' /dev/null");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("\r["), std::string::npos) << r.out;
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

// The configuration's detector options reach the detector: a threshold above the laser's peak
// leaves no point.
TEST_F(LaserlineExtract, ConfigurationOptionsAreUsed) {
  options_.ambient = 10;
  options_.laser_peak = 60;
  options_.texture_contrast = 0;
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f.png"), render(scene, 0)));
  std::ofstream(path("high.yaml")) << "detector:\n  maxvalue: {threshold: 250}\n";
  RunResult r = extract("--config " + path("high.yaml") + " " + path("f.png"));
  EXPECT_EQ(r.exit_code, 3) << "no point in the whole run: " << r.out;
  EXPECT_EQ(read_csv(path("points.csv")).rows, 0u);
  EXPECT_NE(
      r.out.find("laserline-extract: no point accepted in any of the 1 processed frames "
                 "(see --channel, --threshold, --roi, --mask, --laser-pattern, --detector)\n"),
      std::string::npos)
      << r.out;
  r = extract(path("f.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}}, scene);
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

// x y z snr of every point of a PLY file as laserline-extract writes it, the header checked.
std::vector<std::array<float, 4>> read_ply(const std::string& path) {
  static_assert(std::endian::native == std::endian::little, "reads the floats as they are");
  std::ifstream in(path, std::ios::binary);
  std::vector<std::string> header;
  std::string line;
  while (std::getline(in, line) && line != "end_header")
    header.push_back(line);
  EXPECT_EQ(header.size(), 8u);
  if (header.size() != 8u) return {};
  EXPECT_EQ(header[0], "ply");
  EXPECT_EQ(header[1], "format binary_little_endian 1.0");
  EXPECT_EQ(header[3].rfind("element vertex ", 0), 0u);
  EXPECT_EQ(header[4] + header[5] + header[6] + header[7],
            "property float xproperty float yproperty float zproperty float scalar_snr");
  const long count = std::stol(header[3].substr(15));
  std::vector<std::array<float, 4>> points(static_cast<std::size_t>(count));
  in.read(reinterpret_cast<char*>(points.data()), count * 16);
  EXPECT_EQ(in.gcount(), count * 16);
  EXPECT_EQ(in.peek(), EOF) << "nothing after the points";
  return points;
}

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

// The source column names the file, or the video and its frame; a name with a comma or a quote is
// quoted as CSV has it.
TEST_F(LaserlineExtract, SourceColumnNamesEachFramesOrigin) {
  hal::SimScene scene(options_);
  const std::string odd = path("scan,\"1\".png");
  ASSERT_TRUE(cv::imwrite(odd, render(scene, 0)));
  {
    cv::VideoWriter writer(path("scan.mkv"), cv::CAP_FFMPEG,
                           cv::VideoWriter::fourcc('F', 'F', 'V', '1'), 30,
                           cv::Size(kWidth, kHeight), false);
    ASSERT_TRUE(writer.isOpened());
    for (int k = 1; k < 3; ++k)
      writer.write(render(scene, k));
  }
  const RunResult r = extract("'" + odd + "' " + path("scan.mkv"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const Csv csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.sources.at(0), odd);
  EXPECT_EQ(csv.sources.at(1), path("scan.mkv") + " frame 0");
  EXPECT_EQ(csv.sources.at(2), path("scan.mkv") + " frame 1");
  expect_frames_match(csv, {{0, 0}, {1, 1}, {2, 2}}, scene);
  std::ifstream in(path("points.csv"));
  std::string header, first;
  std::getline(in, header);
  std::getline(in, first);
  EXPECT_EQ(first.rfind("0,\"" + path("scan,\"\"1\"\".png") + "\",", 0), 0u) << first;
}

// A red laser over white light: the laser is in red only, the lit texture in all three channels.
TEST_F(LaserlineExtract, ChannelPicksTheLasersColour) {
  hal::SimScene scene(options_);
  const cv::Mat lit = render(scene, 0), unlit = render(scene, 0, false);
  cv::Mat bgr;
  cv::merge(std::vector<cv::Mat>{unlit, unlit, lit}, bgr);
  ASSERT_TRUE(cv::imwrite(path("red.png"), bgr));

  // Green, the default, holds the texture only: whatever is found there is not the laser.
  RunResult r = extract(path("red.png"));
  const Csv green = read_csv(path("points.csv"));
  const Accuracy wrong =
      compare(green.frames.count(0) ? green.frames.at(0) : std::vector<CsvPoint>{},
              truth_of(scene, 0), kTolerancePx);
  EXPECT_LT(wrong.recall(), 0.2) << r.out;

  for (const std::string channel : {"red", "'red - (green + blue) / 2'", "r"}) {
    r = extract("--channel " + channel + " " + path("red.png"));
    EXPECT_EQ(r.exit_code, 0) << channel << ": " << r.out;
    expect_frames_match(read_csv(path("points.csv")), {{0, 0}}, scene);
  }

  r = extract("--channel purple " + path("red.png"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.out), 1u) << r.out;
  EXPECT_EQ(r.out.rfind("laserline-extract: --channel \"purple\": ", 0), 0u) << r.out;
}

// Points outside --roi or the mask are left out; the pixels are not changed (a zeroed border
// would be an edge the band-pass answers). The mask only filters: inside it, the points are those
// of the whole frame. --roi is the region the detector searches: inside it, every point of the
// whole frame and the same line; more candidates where a column's strongest few (max 4) of the
// whole frame lay outside.
TEST_F(LaserlineExtract, RoiAndMaskLeaveOutPointsNotPixels) {
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f.png"), render(scene, 0)));
  const hal::SimGroundTruth truth = truth_of(scene, 0);
  // A rectangle whose top and bottom pass 6 px from the line, within the band-pass's reach.
  float top = kHeight, bottom = 0;
  for (int u = 100; u < 220; ++u) {
    top = std::min(top, truth.position[static_cast<std::size_t>(u)]);
    bottom = std::max(bottom, truth.position[static_cast<std::size_t>(u)]);
  }
  const int y0 = static_cast<int>(std::floor(top)) - 6;
  const int y1 = static_cast<int>(std::ceil(bottom)) + 6;
  const std::string roi = "100," + std::to_string(y0) + ",120," + std::to_string(y1 - y0);

  cv::Mat left_half = cv::Mat::zeros(kHeight, kWidth, CV_8UC1);
  left_half.colRange(0, kWidth / 2).setTo(255);
  ASSERT_TRUE(cv::imwrite(path("mask.png"), left_half));

  struct Case {
    std::string args, detector;
    std::function<bool(const CsvPoint&)> inside;
  };
  const std::vector<Case> cases = {
      {"--roi " + roi, "fir",
       [&](const CsvPoint& p) {
         const long v = std::lround(p.v);
         return p.u >= 100 && p.u < 220 && v >= y0 && v < y1;
       }},
      {"--mask " + path("mask.png"), "maxvalue",
       [](const CsvPoint& p) { return p.u < kWidth / 2; }},
      {"--mask " + path("mask.png") + " --roi " + roi, "maxvalue",
       [&](const CsvPoint& p) { return p.u >= 100 && p.u < kWidth / 2; }},
  };
  for (const auto& c : cases) {
    RunResult r = extract("--all-candidates " + path("f.png"), c.detector);
    ASSERT_EQ(r.exit_code, 0) << r.out;
    const Csv whole = read_csv(path("points.csv"));
    ASSERT_TRUE(whole.frames.count(0)) << r.out;
    std::vector<CsvPoint> expected;
    for (const auto& p : whole.frames.at(0))
      if (c.inside(p)) expected.push_back(p);
    r = extract("--all-candidates " + c.args + " " + path("f.png"), c.detector);
    ASSERT_EQ(r.exit_code, 0) << c.args << ": " << r.out;
    const Csv kept = read_csv(path("points.csv"));
    ASSERT_GE(expected.size(), 55u) << c.args;
    auto same = [](const CsvPoint& a, const CsvPoint& b) {
      return a.u == b.u && a.v == b.v && a.snr_db == b.snr_db && a.valid == b.valid;
    };
    if (c.args.find("--roi") == std::string::npos) {
      ASSERT_EQ(kept.rows, expected.size()) << c.args;
      for (std::size_t i = 0; i < expected.size(); ++i) {
        EXPECT_TRUE(same(kept.frames.at(0)[i], expected[i]))
            << c.args << ": point " << i << " column " << expected[i].u;
      }
      continue;
    }
    for (const CsvPoint& p : kept.frames.at(0))
      EXPECT_TRUE(c.inside(p)) << c.args << ": " << p.u << ", " << p.v;
    // (maxvalue's SNR compares the peak with the mean of the rows searched.)
    const bool snr_of_region = c.detector == "maxvalue";
    for (const CsvPoint& e : expected) {
      EXPECT_NE(std::find_if(kept.frames.at(0).begin(), kept.frames.at(0).end(),
                             [&](const CsvPoint& p) {
                               return snr_of_region ? p.u == e.u && p.v == e.v && p.valid == e.valid
                                                    : same(p, e);
                             }),
                kept.frames.at(0).end())
          << c.args << ": column " << e.u << " row " << e.v << (e.valid ? " (valid)" : "");
    }
  }

  // A mask away from the line: nothing accepted in the whole run. (A --roi there is searched:
  // maxvalue takes each column's brightest pixel of its rows, fir the most line-like texture.)
  cv::Mat top_rows = cv::Mat::zeros(kHeight, kWidth, CV_8UC1);
  top_rows.rowRange(0, 20).setTo(255);
  ASSERT_TRUE(cv::imwrite(path("top.png"), top_rows));
  RunResult r = extract("--mask " + path("top.png") + " " + path("f.png"));
  EXPECT_EQ(r.exit_code, 3) << r.out;
  EXPECT_NE(r.out.find("no point accepted in any of the 1 processed frames"), std::string::npos)
      << r.out;
  // The detector searched those rows alone: points in most columns (where the texture reaches
  // maxvalue's threshold), each in them.
  r = extract("--roi 0,0,320,20 " + path("f.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  const Csv searched = read_csv(path("points.csv"));
  ASSERT_TRUE(searched.frames.count(0)) << r.out;
  EXPECT_GT(searched.frames.at(0).size(), static_cast<std::size_t>(kWidth / 2));
  for (const CsvPoint& p : searched.frames.at(0))
    EXPECT_LT(std::lround(p.v), 20) << p.u;

  ASSERT_TRUE(cv::imwrite(path("small.png"), cv::Mat(80, 100, CV_8UC1, cv::Scalar(255))));
  ASSERT_TRUE(cv::imwrite(path("black.png"), cv::Mat::zeros(kHeight, kWidth, CV_8UC1)));
  const std::string frames = "320x256 frames of the calibration " + calib_;
  for (const auto& [args, line] : std::vector<std::pair<std::string, std::string>>{
           {"--roi 1,2,3",
            "--roi '1,2,3': expected x,y,w,h: left column, top row (from 0), width "
            "and height (from 1) in pixels, e.g. 0,100,1280,600"},
           {"--roi 0,0,0,10",
            "--roi '0,0,0,10': expected x,y,w,h: left column, top row (from 0), "
            "width and height (from 1) in pixels, e.g. 0,100,1280,600"},
           {"--roi 10,0,311,10", "--roi 10,0,311,10: reaches beyond the " + frames},
           {"--mask " + path("small.png"),
            "--mask " + path("small.png") + ": is 100x80 but must have the size of the " + frames},
           {"--mask " + path("black.png"),
            "--mask " + path("black.png") +
                ": no pixel is set (points are kept on non-zero pixels)"},
           {"--mask " + path("nothere.png"),
            "--mask " + path("nothere.png") + ": cannot be read: No such file or directory"},
       }) {
    r = extract(args + " " + path("f.png"));
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(r.out, "laserline-extract: " + line + "\n");
  }
}

TEST_F(LaserlineExtract, ThresholdInTheDetectorsOwnUnit) {
  options_.ambient = 10;
  options_.laser_peak = 60;
  options_.texture_contrast = 0;
  hal::SimScene scene(options_);
  ASSERT_TRUE(cv::imwrite(path("f.png"), render(scene, 0)));
  // maxvalue: a grey level. The line peaks near 60.
  RunResult r = extract("--threshold 250 " + path("f.png"));
  EXPECT_EQ(r.exit_code, 3) << r.out;
  EXPECT_EQ(read_csv(path("points.csv")).rows, 0u);
  r = extract("--threshold 30 " + path("f.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}}, scene);
  // It overrides the configuration's.
  std::ofstream(path("high.yaml")) << "detector:\n  maxvalue: {threshold: 250}\n";
  r = extract("--config " + path("high.yaml") + " --threshold 30 " + path("f.png"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  expect_frames_match(read_csv(path("points.csv")), {{0, 0}}, scene);

  // fir: an SNR in dB; no point of the line reaches 60 dB, every one passes 6.
  r = extract("--threshold 6 " + path("f.png"), "fir");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  const Csv low = read_csv(path("points.csv"));
  ASSERT_TRUE(low.frames.count(0)) << r.out;
  double strongest = 0;
  for (const auto& p : low.frames.at(0))
    strongest = std::max(strongest, p.snr_db);
  ASSERT_LT(strongest, 60.0);
  r = extract("--threshold 60 " + path("f.png"), "fir");
  EXPECT_EQ(r.exit_code, 3) << r.out;
  EXPECT_EQ(read_csv(path("points.csv")).rows, 0u);

  for (const auto& [args, detector, line] : std::vector<std::array<std::string, 3>>{
           {"--threshold 300", "maxvalue",
            "--threshold 300: the maxvalue detector's threshold is a grey level, a whole number "
            "from 1 to 255"},
           {"--threshold 6.5", "maxvalue",
            "--threshold 6.5: the maxvalue detector's threshold is a grey level, a whole number "
            "from 1 to 255"},
           {"--threshold abc", "fir",
            "--threshold abc: the fir detector's threshold is an SNR in dB, a number from 0 to 60"},
           {"--threshold 70", "background",
            "--threshold 70: the background detector's threshold is an SNR in dB, a number from 0 "
            "to 60"},
       }) {
    r = extract(args + " " + path("f.png"), detector);
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(r.out, "laserline-extract: " + line + "\n");
  }
}

// On/off alternation told with --laser-pattern 10: laser-off frames reach the detector (the
// background detector subtracts them from the next frame) but give no points.
TEST_F(LaserlineExtract, LaserPatternOffFramesAreBackgroundsNotLaserFrames) {
  options_.texture_contrast = 0.5;
  hal::SimScene scene(options_);
  fs::create_directories(dir_ / "alt");
  fs::create_directories(dir_ / "more");
  for (int k = 0; k < 5; ++k) {  // on off on off on
    ASSERT_TRUE(
        cv::imwrite(path("alt/f" + std::to_string(k) + ".png"), render(scene, k, k % 2 == 0)));
  }
  for (int k = 5; k < 8; ++k) {  // on off on: the pattern starts again with each folder
    ASSERT_TRUE(
        cv::imwrite(path("more/f" + std::to_string(k) + ".png"), render(scene, k, k % 2 == 1)));
  }
  // Not told: maxvalue takes the texture of the laser-off frames for the laser.
  RunResult r = extract(path("alt"));
  EXPECT_TRUE(read_csv(path("points.csv")).frames.count(1)) << "the hazard the pattern removes";

  r = extract("--laser-pattern 10 --ply " + path("cloud.ply") + " " + path("alt") + " " +
              path("more"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("laserline-extract: 3 of the processed frames were exposed with the laser "
                       "off (3 from --laser-pattern 10): no points taken from them\n"),
            std::string::npos)
      << r.out;
  Csv csv = read_csv(path("points.csv"));
  std::vector<long> frames;
  for (const auto& [frame, points] : csv.frames)
    frames.push_back(frame);
  EXPECT_EQ(frames, (std::vector<long>{0, 2, 4, 5, 7}));
  expect_frames_match(csv, {{0, 0}, {2, 2}, {4, 4}, {5, 5}, {7, 7}}, scene);
  EXPECT_EQ(read_ply(path("cloud.ply")).size(), csv.rows) << "no laser-off points in the cloud";

  // background: each laser-on frame minus the laser-off frame before it (the first has none).
  r = extract("--laser-pattern 10 " + path("alt"), "background");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  csv = read_csv(path("points.csv"));
  EXPECT_EQ(csv.frames.count(1) + csv.frames.count(3), 0u);
  expect_frames_match(csv, {{2, 2}, {4, 4}}, scene);

  for (const auto& [bits, line] : std::vector<std::pair<std::string, std::string>>{
           {"1x0",
            "--laser-pattern '1x0': expected 1 to 1024 characters 0 (laser off) or 1 "
            "(laser on), e.g. 10 for on/off alternation"},
           {"00", "--laser-pattern '00': has no 1, so no frame would have the laser on"},
       }) {
    r = extract("--laser-pattern " + bits + " " + path("alt"));
    EXPECT_EQ(r.exit_code, 2) << bits;
    EXPECT_EQ(r.out, "laserline-extract: " + line + "\n");
  }
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

TEST_F(LaserlineExtract, HelpNamesTheNewFlagsAndExitStatuses) {
  const RunResult r = run_command(std::string(LASERLINE_EXTRACT_PATH) + " --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* text :
       {"--threshold VALUE", "--channel NAME|EXPR", "--roi x,y,w,h", "--mask FILE",
        "--laser-pattern BITS", "frame,source,u,v,x,y,snr_db,segment,valid",
        "folders of images (in natural\n                     order: 2 before 10)",
        "maxvalue a grey level 1..255", "SNR in dB 0..60", "Exit status: 0", "1 some input",
        "2 bad arguments", "3 frames\nwere read but no point was accepted"}) {
    EXPECT_NE(r.out.find(text), std::string::npos) << text;
  }
}

}  // namespace
}  // namespace laserline
