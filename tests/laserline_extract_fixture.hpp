#pragma once
// What the tests of laserline-extract (test_laserline_extract*.cpp) share: the CSV it writes and
// its accuracy against the simulator's ground truth, frames rendered by the simulated scanner,
// the LCM messages and logs it reads, and the fixture that runs the real executable.
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

namespace laserline::extract_test {

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
inline std::vector<std::string> csv_fields(const std::string& line) {
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

inline Csv read_csv(const std::string& path) {
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

inline Accuracy compare(const std::vector<CsvPoint>& points, const hal::SimGroundTruth& truth,
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

inline std::size_t lines(const std::string& text) {
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

inline constexpr int kWidth = 320;
inline constexpr int kHeight = 256;
inline constexpr double kTolerancePx = 0.5;

inline hal::SimSceneOptions scene_options() {
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

inline cv::Mat render(hal::SimScene& scene, std::uint64_t sequence, bool laser_on = true) {
  cv::Mat image(kHeight, kWidth, CV_8UC1);
  scene.render(sequence, laser_on,
               std::span<std::uint8_t>(image.data, static_cast<std::size_t>(kWidth) * kHeight));
  return image;
}

// Frames 0 .. frames-1 of `scene` as a Motion JPEG video at the best quality; false when this
// OpenCV cannot write one.
inline bool write_motion_jpeg(const std::string& video, hal::SimScene& scene, int frames) {
  cv::VideoWriter writer(video, cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30,
                         cv::Size(kWidth, kHeight), false);
  if (!writer.isOpened()) return false;
  writer.set(cv::VIDEOWRITER_PROP_QUALITY, 100);
  for (int k = 0; k < frames; ++k)
    writer.write(render(scene, static_cast<std::uint64_t>(k)));
  return true;
}

inline hal::SimGroundTruth truth_of(const hal::SimScene& scene, std::uint64_t sequence) {
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

inline laserline::image_t image_message(const cv::Mat& image, std::int64_t sequence) {
  laserline::image_t m;
  m.utime = 1'700'000'000'000'000 + sequence * 33'333;
  m.sequence = sequence;
  m.width = image.cols;
  m.height = image.rows;
  m.compression = laserline::image_t::COMPRESSION_NONE;
  return m;
}

inline void write_event(lcm::LogFile& log, const std::string& channel,
                        const std::vector<std::uint8_t>& data, std::int64_t utime) {
  lcm::LogEvent event;
  event.timestamp = utime;
  event.channel = channel;
  event.datalen = static_cast<std::int32_t>(data.size());
  event.data = const_cast<std::uint8_t*>(data.data());
  ASSERT_EQ(log.writeEvent(&event), 0);
}

template <typename Message>
inline std::vector<std::uint8_t> encode(const Message& m) {
  std::vector<std::uint8_t> data(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(data.data(), 0, static_cast<int>(data.size())), static_cast<int>(data.size()));
  return data;
}

// What laserlined publishes on LASERLINE_CALIBRATION, written here field by field.
inline laserline::calibration_t calibration_message(const hal::Calibration& c) {
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
  const Eigen::Vector4d plane = c.laser.plane_coefficients();
  std::copy(plane.begin(), plane.end(), m.laser_plane);
  m.sheet_width_m = c.laser.sheet_width_m;
  return m;
}

// A log of frames 0 and 1 as a daemon of `calibration` records it: its calibration_t first
// (unless left out), then each frame's image_t and a profile naming the calibration.
inline void write_dive(const std::string& log_path, hal::SimScene& scene,
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

// Whether `line` is `before`, a whole number, then `after` (a byte offset that depends on how
// OpenCV splits its PNG data into chunks).
inline bool is_with_number(const std::string& line, const std::string& before,
                           const std::string& after) {
  if (line.size() <= before.size() + after.size() || line.rfind(before, 0) != 0 ||
      line.compare(line.size() - after.size(), after.size(), after) != 0) {
    return false;
  }
  const std::string number = line.substr(before.size(), line.size() - before.size() - after.size());
  return number.find_first_not_of("0123456789") == std::string::npos;
}

// The line of `out` that begins with `start` ("" when none).
inline std::string line_starting(const std::string& out, const std::string& start) {
  const std::size_t at = out.find(start);
  return at == std::string::npos ? "" : out.substr(at, out.find('\n', at) - at);
}

// Bytes of a file, written or read whole.
inline void write_bytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}
inline std::vector<std::uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// x y z snr of every point of a PLY file as laserline-extract writes it, the header checked.
inline std::vector<std::array<float, 4>> read_ply(const std::string& path) {
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

}  // namespace laserline::extract_test
