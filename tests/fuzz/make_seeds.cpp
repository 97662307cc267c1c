// Writes the fuzz harnesses' seed corpora: real messages encoded by lcm-gen's code (profiles,
// status, points, raw frames uncompressed, zlib, PNG and JPEG), an LCM log holding them, and a
// calibration in OpenCV's FileStorage layout. Usage: make_fuzz_seeds CORPUS_DIR
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "lcmtypes/checked_decode.hpp"

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

template <typename Message>
Bytes encode(const Message& m) {
  Bytes out(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(out.data(), 0, static_cast<int>(out.size()));
  return out;
}

void write(const fs::path& path, const Bytes& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

void put_be(Bytes& out, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i)
    out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

// One LCM log event as lcm-logger writes it.
void log_event(Bytes& log, std::int64_t number, const std::string& channel, const Bytes& data) {
  put_be(log, 0xEDA1DA01, 4);
  put_be(log, static_cast<std::uint64_t>(number), 8);
  put_be(log, 1'700'000'000'000'000ULL + static_cast<std::uint64_t>(number) * 50'000, 8);
  put_be(log, channel.size(), 4);
  put_be(log, data.size(), 4);
  log.insert(log.end(), channel.begin(), channel.end());
  log.insert(log.end(), data.begin(), data.end());
}

laserline::profile_t profile(int points) {
  laserline::profile_t p;
  p.utime = 1'700'000'000'123'456;
  p.sequence = 42;
  p.camera_timestamp_ns = 987'654'321;
  p.laser_on = true;
  p.width = 64;
  p.height = 48;
  p.detector = "maxvalue";
  p.background_sequence = -1;
  p.background_laser_off = false;
  p.search_axis = laserline::profile_t::SEARCH_COLUMNS;
  p.search_origin[0] = p.search_origin[1] = 0;
  p.search_line_step[0] = 1;
  p.search_line_step[1] = 0;
  p.search_along[0] = 0;
  p.search_along[1] = 1;
  for (int i = 0; i < points; ++i) {
    laserline::point_t pt{};
    pt.u = static_cast<std::int16_t>(i);
    pt.v = 20.25f + 0.1f * static_cast<float>(i);
    pt.snr_db = 18.5f;
    pt.segment = i < points / 2 ? 0 : 1;
    pt.valid = i % 7 != 3;
    pt.xyz[0] = 0.01f * static_cast<float>(i);
    pt.xyz[1] = 0.02f;
    pt.xyz[2] = i % 5 == 0 ? NAN : 1.5f;
    p.points.push_back(pt);
  }
  p.num_points = points;
  p.instance_id = 0x1234'5678'9abc'def0;
  p.exposure_us = 2000;
  p.gain_db = NAN;
  p.calibration_id = 0x0fed'cba9'8765'4321;
  return p;
}

laserline::calibration_t calibration() {
  laserline::calibration_t c{};
  c.utime = 1'700'000'000'000'000;
  c.calibration_id = 0x0fed'cba9'8765'4321;
  c.width = 64;
  c.height = 48;
  c.fx = c.fy = 70;
  c.cx = 31.5;
  c.cy = 23.5;
  c.distortion[0] = -0.1;
  c.laser_plane[1] = 1;
  c.laser_plane[2] = -0.17;
  c.laser_plane[3] = 0.25;
  c.sheet_width_m = 0.003;
  c.instance_id = 0x1234'5678'9abc'def0;
  return c;
}

laserline::status_t status() {
  laserline::status_t s{};
  s.utime = 1'700'000'001'000'000;
  s.uptime_us = 12'000'000;
  s.camera_backend = "sim";
  s.detector = "maxvalue";
  s.camera_state = "streaming";
  s.laser_on = true;
  s.frames_captured = 240;
  s.frames_processed = 239;
  s.frame_rate_hz = 20;
  s.points_per_profile = 63.5f;
  s.latency_samples = 20;
  s.latency_p50_ms = 3.5f;
  s.cpu_percent = 23.5f;
  s.bad_messages = 2;
  s.bad_frames = 1;
  s.instance_id = 0x1234'5678'9abc'def0;
  s.strobe_state = "silent: no edge on line 'STROBE' of gpiochip0 (chip) since start";
  s.strobe_unmatched_frames = 239;
  return s;
}

cv::Mat frame(int width, int height) {
  cv::Mat m(height, width, CV_8UC1);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      m.at<std::uint8_t>(y, x) =
          static_cast<std::uint8_t>(y == 20 + x / 8 ? 250 : (x * 3 + y) % 40);
  return m;
}

laserline::image_t image(const cv::Mat& grey, std::int8_t compression) {
  laserline::image_t m{};
  m.utime = 1'700'000'000'123'456;
  m.sequence = 42;
  m.laser_on = true;
  m.width = grey.cols;
  m.height = grey.rows;
  m.row_stride = grey.cols;
  m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
  m.compression = compression;
  m.downscale = 1;
  if (compression == laserline::image_t::COMPRESSION_NONE) {
    m.data.assign(grey.data, grey.data + grey.total());
  } else if (compression == laserline::image_t::COMPRESSION_ZLIB) {
    uLongf size = compressBound(static_cast<uLong>(grey.total()));
    m.data.resize(size);
    compress(m.data.data(), &size, grey.data, static_cast<uLong>(grey.total()));
    m.data.resize(size);
  } else {
    cv::imencode(compression == laserline::image_t::COMPRESSION_PNG ? ".png" : ".jpg", grey,
                 m.data);
  }
  m.size = static_cast<std::int32_t>(m.data.size());
  return m;
}

// The image_payload harness's input: its 12-byte header, then the payload.
Bytes payload_seed(const laserline::image_t& m, int format_index) {
  Bytes out = {static_cast<std::uint8_t>(m.width),
               static_cast<std::uint8_t>(m.width >> 8),
               static_cast<std::uint8_t>(m.height),
               static_cast<std::uint8_t>(m.height >> 8),
               static_cast<std::uint8_t>(m.row_stride),
               static_cast<std::uint8_t>(m.row_stride >> 8),
               0,
               0,
               static_cast<std::uint8_t>(format_index),
               static_cast<std::uint8_t>(m.compression),
               0,
               0};
  out.insert(out.end(), m.data.begin(), m.data.end());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_fuzz_seeds CORPUS_DIR\n");
    return 2;
  }
  const fs::path dir = argv[1];
  const Bytes profile_small = encode(profile(3)), profile_full = encode(profile(64)),
              profile_empty = encode(profile(0)), status_bytes = encode(status());
  write(dir / "profile/small", profile_small);
  write(dir / "profile/full", profile_full);
  write(dir / "profile/empty", profile_empty);
  write(dir / "status/status", status_bytes);
  for (auto [name, value] : {std::pair{"exposure_us", "1500"}, std::pair{"laser.mode", "off"},
                             std::pair{"genicam:ExposureTime", "800"}, std::pair{"get", ""}}) {
    laserline::command_t command;
    command.utime = 1'700'000'000'000'000;
    command.id = 7;
    command.sender = "laserline-ctl@rov[42]";
    command.name = name;
    command.value = value;
    command.token = "s3cret";
    write(dir / "command" / (std::string(name) + ".cmd"), encode(command));
  }
  write(dir / "point/point", encode(profile(1).points[0]));
  const Bytes calibration_bytes = encode(calibration());
  write(dir / "calibration_message/calibration", calibration_bytes);

  const cv::Mat grey = frame(64, 48);
  Bytes log;
  std::int64_t number = 0;
  log_event(log, number++, "LASERLINE_STATUS", status_bytes);
  log_event(log, number++, "LASERLINE_CALIBRATION", calibration_bytes);
  const char* names[] = {"none", "png", "jpeg", "zlib"};
  for (std::int8_t c = 0; c < 4; ++c) {
    const laserline::image_t m = image(grey, c);
    const Bytes bytes = encode(m);
    write(dir / "image_message" / names[c], bytes);
    write(dir / "image_payload" / names[c], payload_seed(m, 0));
    log_event(log, number++, "LASERLINE_IMAGE", bytes);
    log_event(log, number++, "LASERLINE_PROFILE", profile_full);
  }
  // A 16-bit little-endian frame, uncompressed, with a stride wider than its rows.
  {
    laserline::image_t m = image(grey, laserline::image_t::COMPRESSION_NONE);
    m.width = 16;
    m.height = 8;
    m.row_stride = 40;
    m.pixelformat = laserline::image_t::PIXEL_FORMAT_LE_GRAY16;
    m.data.resize(static_cast<std::size_t>(m.row_stride * m.height));
    m.size = static_cast<std::int32_t>(m.data.size());
    write(dir / "image_message/gray16", encode(m));
    write(dir / "image_payload/gray16", payload_seed(m, 1));
  }
  log_event(log, number++, "SOMEONE_ELSE", {1, 2, 3});
  write(dir / "lcm_log/short.lcmlog", log);

  // A calibration as OpenCV's calibration sample writes it, with laserline's laser section.
  const fs::path calibration = dir / "calibration/opencv.yml";
  fs::create_directories(calibration.parent_path());
  {
    cv::FileStorage out(calibration.string(), cv::FileStorage::WRITE);
    out << "image_width" << 1280 << "image_height" << 1024;
    out << "camera_matrix"
        << cv::Mat((cv::Mat_<double>(3, 3) << 1402.5, 0, 641.25, 0, 1398.75, 509.5, 0, 0, 1));
    out << "distortion_coefficients"
        << cv::Mat((cv::Mat_<double>(5, 1) << -0.12, 0.034, 0.0011, -0.0007, 0.0021));
    out << "laser"
        << "{"
        << "baseline_m" << 0.25 << "angle_deg" << 80 << "sheet_width_m" << 0.003 << "}";
  }
  // ROS's camera_info file and Kalibr's camchain file, each with a laser section.
  std::ofstream(dir / "calibration/ros.yaml")
      << "image_width: 1280\nimage_height: 1024\ncamera_name: ptu_camera\n"
         "camera_matrix:\n  rows: 3\n  cols: 3\n"
         "  data: [1402.5, 0.0, 641.25, 0.0, 1398.75, 509.5, 0.0, 0.0, 1.0]\n"
         "distortion_model: plumb_bob\n"
         "distortion_coefficients:\n  rows: 1\n  cols: 5\n"
         "  data: [-0.12, 0.034, 0.0011, -0.0007, 0.0021]\n"
         "rectification_matrix:\n  rows: 3\n  cols: 3\n"
         "  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n"
         "projection_matrix:\n  rows: 3\n  cols: 4\n"
         "  data: [1380.0, 0.0, 640.0, 0.0, 0.0, 1380.0, 510.0, 0.0, 0.0, 0.0, 1.0, 0.0]\n"
         "laser: {baseline_m: 0.25, angle_deg: 80}\n";
  std::ofstream(dir / "calibration/kalibr.yaml")
      << "cam0:\n  T_cam_imu:\n  - [0.0, -1.0, 0.0, 0.05]\n  - [1.0, 0.0, 0.0, 0.0]\n"
         "  - [0.0, 0.0, 1.0, -0.02]\n  - [0.0, 0.0, 0.0, 1.0]\n  cam_overlaps: []\n"
         "  camera_model: pinhole\n  distortion_coeffs: [-0.25, 0.125, 0.0005, -0.001]\n"
         "  distortion_model: radtan\n  intrinsics: [1401.5, 1399.25, 640.75, 509.5]\n"
         "  resolution: [1280, 1024]\n  rostopic: /ptu/camera/image_raw\n"
         "laser: {plane: [0, 0.98, -0.17, 0.25]}\n";
  return 0;
}
