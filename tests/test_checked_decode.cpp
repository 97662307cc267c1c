// lcmtypes/checked_decode: every message of ours decoded only after its lengths are checked; the
// crafted messages of issue 15 (negative or huge string lengths, num_points = -1, image_t.size =
// -1 or 0x7fffffff, row_stride = -1) refused in one line without an exception or a big
// allocation; what is accepted encodes back to the same bytes.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "lcmtypes/checked_decode.hpp"

namespace {

using laserline::messages::decode;
using laserline::messages::Limits;
using Bytes = std::vector<std::uint8_t>;

template <typename Message>
Bytes encode(const Message& m) {
  Bytes out(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(out.data(), 0, static_cast<int>(out.size())), static_cast<int>(out.size()));
  return out;
}

void put_i32(Bytes& bytes, std::size_t at, std::int32_t value) {
  for (int i = 0; i < 4; ++i)
    bytes[at + static_cast<std::size_t>(i)] =
        static_cast<std::uint8_t>(static_cast<std::uint32_t>(value) >> (24 - 8 * i));
}

laserline::profile_t profile(int points) {
  laserline::profile_t p{};
  p.sequence = 7;
  p.detector = "maxvalue";
  for (int i = 0; i < points; ++i) {
    laserline::point_t pt{};
    pt.u = static_cast<std::int16_t>(i);
    pt.v = 1.5f;
    pt.xyz[2] = NAN;
    p.points.push_back(pt);
  }
  p.num_points = points;
  p.instance_id = -5;
  p.exposure_us = 2500;
  p.gain_db = NAN;  // not reported
  p.calibration_id = static_cast<std::int64_t>(0x8000'0000'0000'0001);
  return p;
}

laserline::calibration_t calibration() {
  laserline::calibration_t c{};
  c.utime = 1'700'000'000'000'000;
  c.calibration_id = 0x252c9bdbd4951ce8;
  c.width = 1280;
  c.height = 1024;
  c.fx = c.fy = 1400;
  c.cx = 639.5;
  c.cy = 511.5;
  c.laser_plane[1] = 1;
  c.laser_plane[2] = -0.176;
  c.laser_plane[3] = 0.25;
  c.sheet_width_m = 0.003;
  c.instance_id = 0x0123456789abcdef;
  return c;
}

laserline::status_t status() {
  laserline::status_t s{};
  s.camera_backend = "lcm";
  s.detector = "maxvalue";
  s.camera_state = "streaming";
  s.frames_processed = 301;
  s.camera_other_errors = 3;
  s.bad_messages = 4;
  s.bad_frames = 5;
  s.instance_id = 0x0123456789abcdef;
  s.strobe_state = "silent: no edge on line 'STROBE' of gpiochip0 (chip) since start";
  s.strobe_unmatched_frames = 239;
  return s;
}

laserline::image_t image(int width, int height) {
  laserline::image_t m{};
  m.width = width;
  m.height = height;
  m.row_stride = width;
  m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
  m.compression = laserline::image_t::COMPRESSION_NONE;
  m.downscale = 1;
  m.data.resize(static_cast<std::size_t>(width * height));
  for (std::size_t i = 0; i < m.data.size(); ++i)
    m.data[i] = static_cast<std::uint8_t>(i * 7);
  m.size = static_cast<std::int32_t>(m.data.size());
  return m;
}

// Every prefix of a valid message is refused with a reason, none throws.
template <typename Message>
void every_prefix_refused(const Bytes& bytes) {
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    Message m;
    std::string problem;
    EXPECT_FALSE(decode(bytes.data(), n, &m, Limits{}, &problem)) << n;
    EXPECT_FALSE(problem.empty()) << n;
  }
}

TEST(CheckedDecode, RealMessagesRoundTripAndEveryPrefixIsRefused) {
  std::string problem;
  for (int points : {0, 1, 500}) {
    const Bytes bytes = encode(profile(points));
    laserline::profile_t back;
    ASSERT_TRUE(decode(bytes.data(), bytes.size(), &back, Limits{}, &problem)) << problem;
    EXPECT_EQ(encode(back), bytes);
    EXPECT_EQ(back.num_points, points);
    EXPECT_EQ(back.instance_id, -5);
    EXPECT_EQ(back.exposure_us, 2500);
    EXPECT_TRUE(std::isnan(back.gain_db));
    EXPECT_EQ(static_cast<std::uint64_t>(back.calibration_id), 0x8000'0000'0000'0001u);
  }
  every_prefix_refused<laserline::profile_t>(encode(profile(3)));
  const Bytes s = encode(status());
  laserline::status_t sb;
  ASSERT_TRUE(decode(s.data(), s.size(), &sb, Limits{}, &problem)) << problem;
  EXPECT_EQ(encode(sb), s);
  EXPECT_EQ(sb.bad_frames, 5);
  EXPECT_EQ(sb.instance_id, 0x0123456789abcdef);
  EXPECT_EQ(sb.strobe_state, status().strobe_state);
  EXPECT_EQ(sb.strobe_unmatched_frames, 239);
  every_prefix_refused<laserline::status_t>(s);
  const Bytes i = encode(image(16, 8));
  laserline::image_t ib;
  ASSERT_TRUE(decode(i.data(), i.size(), &ib, Limits{}, &problem)) << problem;
  EXPECT_EQ(encode(ib), i);
  every_prefix_refused<laserline::image_t>(i);
  const Bytes pt = encode(profile(1).points[0]);
  laserline::point_t pb;
  ASSERT_TRUE(decode(pt.data(), pt.size(), &pb, Limits{}, &problem)) << problem;
  every_prefix_refused<laserline::point_t>(pt);
  // Trailing bytes and another type's fingerprint.
  Bytes longer = i;
  longer.push_back(0);
  EXPECT_FALSE(decode(longer.data(), longer.size(), &ib, Limits{}, &problem));
  EXPECT_EQ(problem, "1 bytes after the end of the laserline.image_t (207 of 208 bytes used)");
  const Bytes c = encode(calibration());
  laserline::calibration_t cb;
  ASSERT_TRUE(decode(c.data(), c.size(), &cb, Limits{}, &problem)) << problem;
  EXPECT_EQ(encode(cb), c);
  EXPECT_EQ(cb.calibration_id, 0x252c9bdbd4951ce8);
  EXPECT_EQ(cb.laser_plane[3], 0.25);
  every_prefix_refused<laserline::calibration_t>(c);
  EXPECT_FALSE(decode(s.data(), s.size(), &ib, Limits{}, &problem));
  EXPECT_EQ(problem, "not a laserline.image_t (another type's fingerprint)");
}

// Offsets in the encodings: the profile's detector length after hash 8, 3 int64, a boolean and
// width and height; status' camera_backend length after hash 8 and 2 int64.
constexpr std::size_t kDetectorAt = 8 + 24 + 1 + 8;
constexpr std::size_t kCameraBackendAt = 8 + 16;
constexpr std::size_t kImageSizeAt = 8 + 24 + 1 + 16 + 1 + 8 + 1;

TEST(CheckedDecode, CraftedLengthsAreRefusedInOneLine) {
  std::string problem;
  laserline::profile_t p;
  for (std::int32_t length : {-1, 0, 0x7fffffff, 258}) {
    Bytes bytes = encode(profile(2));
    put_i32(bytes, kDetectorAt, length);
    EXPECT_FALSE(decode(bytes.data(), bytes.size(), &p, Limits{}, &problem));
    EXPECT_EQ(problem, "detector at byte 41: length " + std::to_string(length) + " outside 1..257");
  }
  const std::size_t num_points_at = kDetectorAt + 4 + 9 + 8 + 1 + 1 + 48;
  // 4 points of 23 bytes do not fit in the 2 points and the 32 bytes after them.
  for (std::int32_t n : {-1, 0x7fffffff, 4}) {
    Bytes bytes = encode(profile(2));
    put_i32(bytes, num_points_at, n);
    EXPECT_FALSE(decode(bytes.data(), bytes.size(), &p, Limits{}, &problem)) << n;
    EXPECT_NE(problem.find("num_points at byte " + std::to_string(num_points_at) + ": " +
                           std::to_string(n)),
              std::string::npos)
        << problem;
  }
  laserline::status_t s;
  Bytes bytes = encode(status());
  put_i32(bytes, kCameraBackendAt, -1);
  EXPECT_FALSE(decode(bytes.data(), bytes.size(), &s, Limits{}, &problem));
  EXPECT_EQ(problem, "camera_backend at byte 24: length -1 outside 1..257");
  laserline::image_t m;
  for (std::int32_t size : {-1, 0x7fffffff}) {
    Bytes image_bytes = encode(image(16, 8));
    put_i32(image_bytes, kImageSizeAt, size);
    EXPECT_FALSE(decode(image_bytes.data(), image_bytes.size(), &m, Limits{}, &problem));
    EXPECT_EQ(problem, "size at byte 59: " + std::to_string(size) + " outside 0..67108864");
  }
  // A calibration_t cut short in its laser plane, one with a byte too many, another type.
  laserline::calibration_t c;
  const Bytes calibration_bytes = encode(calibration());
  EXPECT_EQ(calibration_bytes.size(), 8u + 16 + 8 + 32 + 40 + 32 + 8 + 8);
  EXPECT_FALSE(decode(calibration_bytes.data(), 8 + 16 + 8 + 32 + 40 + 10, &c, Limits{}, &problem));
  EXPECT_EQ(problem, "laser_plane at byte 104 runs past the end (114 bytes)");
  Bytes longer = calibration_bytes;
  longer.push_back(0);
  EXPECT_FALSE(decode(longer.data(), longer.size(), &c, Limits{}, &problem));
  EXPECT_EQ(problem,
            "1 bytes after the end of the laserline.calibration_t (152 of 153 bytes used)");
  const Bytes status_bytes = encode(status());
  EXPECT_FALSE(decode(status_bytes.data(), status_bytes.size(), &c, Limits{}, &problem));
  EXPECT_EQ(problem, "not a laserline.calibration_t (another type's fingerprint)");
}

TEST(CheckedDecode, ImagePixelsAreBoundedByTheirBytes) {
  Limits limits;
  limits.max_width = 64;
  limits.max_height = 64;
  cv::Mat out;
  std::string problem;
  laserline::image_t m = image(16, 8);
  ASSERT_TRUE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem));
  EXPECT_EQ(out.at<std::uint8_t>(1, 2), static_cast<std::uint8_t>(18 * 7));
  m.row_stride = -1;
  EXPECT_FALSE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem));
  EXPECT_EQ(problem, "row_stride -1 and 128 bytes do not hold a 16x8 frame");
  m.row_stride = 17;
  EXPECT_FALSE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem));
  m = image(16, 8);
  m.height = 100;
  EXPECT_FALSE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem));
  EXPECT_EQ(problem, "frame size 16x100 outside 1x1..64x64");
  // A zlib bomb: 64 MB of zeros in a few kB unpack to no more than the frame's 128 bytes.
  m = image(16, 8);
  m.compression = laserline::image_t::COMPRESSION_ZLIB;
  Bytes zeros(64 << 20);
  uLongf packed = compressBound(static_cast<uLong>(zeros.size()));
  m.data.resize(packed);
  ASSERT_EQ(compress(m.data.data(), &packed, zeros.data(), static_cast<uLong>(zeros.size())), Z_OK);
  m.data.resize(packed);
  m.size = static_cast<std::int32_t>(packed);
  EXPECT_FALSE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem));
  EXPECT_EQ(problem, "zlib data do not unpack to a 16x8 frame (buffer error)");
  // A PNG whose header says another size than the message is not decoded.
  m = image(16, 8);
  m.compression = laserline::image_t::COMPRESSION_PNG;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(8, 32, CV_8UC1, cv::Scalar(9)), m.data));
  m.size = static_cast<std::int32_t>(m.data.size());
  EXPECT_FALSE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem));
  EXPECT_EQ(problem, "compressed image is 32x8, the message says 16x8");
  ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(8, 16, CV_8UC1, cv::Scalar(9)), m.data));
  m.compression = laserline::image_t::COMPRESSION_JPEG;
  m.size = static_cast<std::int32_t>(m.data.size());
  ASSERT_TRUE(laserline::messages::unpack_image(m, limits, cv::IMREAD_GRAYSCALE, &out, &problem))
      << problem;
  EXPECT_EQ(out.cols, 16);
}

}  // namespace

namespace {

laserline::command_t command() {
  laserline::command_t c{};
  c.utime = 1'700'000'000'000'000;
  c.id = 42;
  c.sender = "laserline-ctl@rov";
  c.name = "exposure_us";
  c.value = "1500";
  c.token = "";
  return c;
}

laserline::command_ack_t command_ack() {
  laserline::command_ack_t a{};
  a.id = 42;
  a.name = "exposure_us";
  a.accepted = true;
  a.reason = "";
  a.value = "1500";
  a.old_value = "1000";
  a.instance_id = -3;
  return a;
}

}  // namespace

// command_t and command_ack_t: bounded like the others; a string length in them that lies, or a
// string over the limit, is one line naming the field and its byte.
TEST(CheckedDecode, CommandsAndTheirAnswersAreBounded) {
  std::string problem;
  const Bytes c = encode(command());
  laserline::command_t cb;
  ASSERT_TRUE(decode(c.data(), c.size(), &cb, Limits{}, &problem)) << problem;
  EXPECT_EQ(encode(cb), c);
  EXPECT_EQ(cb.value, "1500");
  every_prefix_refused<laserline::command_t>(c);
  const Bytes a = encode(command_ack());
  laserline::command_ack_t ab;
  ASSERT_TRUE(decode(a.data(), a.size(), &ab, Limits{}, &problem)) << problem;
  EXPECT_EQ(encode(ab), a);
  EXPECT_EQ(ab.old_value, "1000");
  every_prefix_refused<laserline::command_ack_t>(a);

  // The sender's length (after the hash and two int64) made negative, then huge.
  constexpr std::size_t kSenderAt = 8 + 16;
  for (std::int32_t length : {-1, 0x7fffffff}) {
    Bytes bytes = c;
    put_i32(bytes, kSenderAt, length);
    EXPECT_FALSE(decode(bytes.data(), bytes.size(), &cb, Limits{}, &problem));
    EXPECT_EQ(problem, "sender at byte 24: length " + std::to_string(length) + " outside 1..257");
  }
  laserline::command_t long_value = command();
  long_value.value = std::string(300, '1');
  const Bytes too_long = encode(long_value);
  EXPECT_FALSE(decode(too_long.data(), too_long.size(), &cb, Limits{}, &problem));
  EXPECT_EQ(problem, "value at byte 62: length 301 outside 1..257");
  EXPECT_FALSE(decode(a.data(), a.size(), &cb, Limits{}, &problem));
  EXPECT_EQ(problem, "not a laserline.command_t (another type's fingerprint)");
}
