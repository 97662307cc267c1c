// Raw frames for LASERLINE_IMAGE: region, downscale and each compression, decoded back the way a
// subscriber (or the replay camera) does, and the replay camera reading compressed frames.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "daemon/lcm_camera.hpp"
#include "daemon/raw_frame_encoder.hpp"

namespace {

using laserline::daemon::ImageCompression;
using laserline::daemon::ImageSlot;
using laserline::daemon::RawFrameEncoder;
using laserline::daemon::RawFrameOptions;

constexpr int kW = 64;
constexpr int kH = 48;

ImageSlot test_frame() {
  ImageSlot slot;
  slot.format = {kW, kH, kW, laserline::hal::PixelFormat::kMono8};
  slot.pixels.resize(static_cast<std::size_t>(kW * kH));
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x)
      slot.pixels[static_cast<std::size_t>(y * kW + x)] = static_cast<std::uint8_t>(x * 3 + y * 5);
  }
  return slot;
}

// The pixels of an encoded message, decoded as a subscriber would.
std::vector<std::uint8_t> decode(const laserline::image_t& m) {
  const std::size_t bytes = static_cast<std::size_t>(m.width) * m.height;
  std::vector<std::uint8_t> out(bytes);
  if (m.compression == laserline::image_t::COMPRESSION_NONE) {
    EXPECT_EQ(m.data.size(), bytes);
    std::copy(m.data.begin(), m.data.end(), out.begin());
  } else if (m.compression == laserline::image_t::COMPRESSION_ZLIB) {
    uLongf got = static_cast<uLongf>(bytes);
    EXPECT_EQ(uncompress(out.data(), &got, m.data.data(), static_cast<uLong>(m.data.size())), Z_OK);
    EXPECT_EQ(got, bytes);
  } else {
    const cv::Mat d = cv::imdecode(cv::Mat(1, static_cast<int>(m.data.size()), CV_8UC1,
                                           const_cast<std::uint8_t*>(m.data.data())),
                                   cv::IMREAD_GRAYSCALE);
    EXPECT_EQ(d.cols, m.width);
    EXPECT_EQ(d.rows, m.height);
    if (d.cols == m.width && d.rows == m.height) std::copy(d.data, d.data + bytes, out.begin());
  }
  EXPECT_EQ(static_cast<std::size_t>(m.size), m.data.size());
  return out;
}

laserline::image_t encode(const RawFrameOptions& options, const ImageSlot& slot) {
  RawFrameEncoder encoder(options, slot.format);
  laserline::image_t m;
  EXPECT_TRUE(encoder.encode(slot, &m));
  return m;
}

TEST(RawFrameEncoder, LosslessCompressionsGiveTheFrameBack) {
  const ImageSlot slot = test_frame();
  for (auto [c, code] : {std::pair{ImageCompression::kNone, laserline::image_t::COMPRESSION_NONE},
                         std::pair{ImageCompression::kZlib, laserline::image_t::COMPRESSION_ZLIB},
                         std::pair{ImageCompression::kPng, laserline::image_t::COMPRESSION_PNG}}) {
    RawFrameOptions o;
    o.downscale = 1;
    o.compression = c;
    const laserline::image_t m = encode(o, slot);
    EXPECT_EQ(m.compression, code);
    EXPECT_EQ(m.width, kW);
    EXPECT_EQ(m.height, kH);
    EXPECT_EQ(m.downscale, 1);
    EXPECT_EQ(decode(m), slot.pixels) << "compression " << static_cast<int>(code);
    if (c != ImageCompression::kNone) {
      EXPECT_LT(m.data.size(), slot.pixels.size());
    }
  }
}

TEST(RawFrameEncoder, JpegIsCloseAndSmaller) {
  const ImageSlot slot = test_frame();
  RawFrameOptions o;
  o.downscale = 1;
  o.compression = ImageCompression::kJpeg;
  o.jpeg_quality = 95;
  const laserline::image_t m = encode(o, slot);
  EXPECT_EQ(m.compression, std::int8_t{laserline::image_t::COMPRESSION_JPEG});
  const auto back = decode(m);
  int worst = 0;
  for (std::size_t i = 0; i < back.size(); ++i)
    worst = std::max(worst, std::abs(int(back[i]) - int(slot.pixels[i])));
  EXPECT_LE(worst, 8);
  EXPECT_LT(m.data.size(), slot.pixels.size());
}

TEST(RawFrameEncoder, RegionAndDownscaleAreStatedAndMeanOfEachBlock) {
  const ImageSlot slot = test_frame();
  RawFrameOptions o;
  o.roi_x = 8;
  o.roi_y = 4;
  o.roi_width = 32;
  o.roi_height = 24;
  o.downscale = 4;
  o.compression = ImageCompression::kZlib;
  const laserline::image_t m = encode(o, slot);
  EXPECT_EQ(m.width, 8);
  EXPECT_EQ(m.height, 6);
  EXPECT_EQ(m.roi_x, 8);
  EXPECT_EQ(m.roi_y, 4);
  EXPECT_EQ(m.downscale, 4);
  const auto back = decode(m);
  for (int y = 0; y < 6; ++y) {
    for (int x = 0; x < 8; ++x) {
      int sum = 0;
      for (int dy = 0; dy < 4; ++dy) {
        for (int dx = 0; dx < 4; ++dx)
          sum += slot.pixels[static_cast<std::size_t>((4 + y * 4 + dy) * kW + 8 + x * 4 + dx)];
      }
      EXPECT_EQ(back[static_cast<std::size_t>(y * 8 + x)], (sum + 8) / 16) << x << "," << y;
    }
  }
}

// A recording made with zlib or PNG raw frames replays the exact frames.
TEST(RawFrameEncoder, CompressedRecordingsReplayExactly) {
  const ImageSlot slot = test_frame();
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("laserline_compressed_" + std::to_string(getpid()) + ".lcmlog"))
                               .string();
  {
    lcm::LogFile log(path, "w");
    std::int64_t sequence = 0;
    for (ImageCompression c :
         {ImageCompression::kZlib, ImageCompression::kPng, ImageCompression::kNone}) {
      RawFrameOptions o;
      o.downscale = 1;
      o.compression = c;
      laserline::image_t m = encode(o, slot);
      m.utime = 1;
      m.sequence = sequence++;
      m.camera_timestamp_ns = 0;
      m.laser_on = true;
      std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
      m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
      lcm::LogEvent e;
      e.timestamp = 0;
      e.channel = "LASERLINE_IMAGE";
      e.datalen = static_cast<std::int32_t>(bytes.size());
      e.data = bytes.data();
      ASSERT_EQ(log.writeEvent(&e), 0);
    }
  }
  laserline::daemon::LcmCamera camera({"file://" + path, "LASERLINE_IMAGE", kW, kH});
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(slot.pixels.size());
  laserline::hal::FrameInfo info;
  int frames = 0;
  ::testing::internal::CaptureStderr();
  while (camera.grab(pixels, info, std::chrono::milliseconds(100)) ==
         laserline::hal::GrabStatus::kOk) {
    EXPECT_EQ(pixels, slot.pixels) << "frame " << frames;
    ++frames;
  }
  const std::string errors = ::testing::internal::GetCapturedStderr();
  std::filesystem::remove(path);
  EXPECT_EQ(frames, 3) << errors;
}

}  // namespace

namespace {

// A region reaching past the frame, however its x + width is computed, is refused by name before
// any buffer is sized from it (x = 2^31 - 1 overflowed to a negative end and read far outside the
// frame; width = 2^31 - 1 allocated 8 GB).
TEST(RawFrameEncoder, RegionOutsideTheFrameIsRefusedBeforeAnyBuffer) {
  const laserline::hal::FrameFormat format{kW, kH, kW, laserline::hal::PixelFormat::kMono8};
  struct Case {
    int x, y, width, height, downscale;
    const char* problem;
  };
  const Case cases[] = {
      {2147483647, 0, 16, 16, 1,
       "lcm.image_roi: [2147483647, 0, 16, 16] is not inside the camera's 64x48 frame"},
      {1, 0, 2147483647, 16, 2,
       "lcm.image_roi: [1, 0, 2147483647, 16] is not inside the camera's 64x48 frame"},
      {0, 2147483640, 8, 2147483647, 1,
       "lcm.image_roi: [0, 2147483640, 8, 2147483647] is not inside the camera's 64x48 frame"},
      {-8, 0, 16, 16, 1, "lcm.image_roi: [-8, 0, 16, 16] is not inside the camera's 64x48 frame"},
      {60, 44, 4, 3, 4, "lcm.image_downscale: 4 leaves no pixel of a 4x3 region"},
  };
  for (const Case& c : cases) {
    RawFrameOptions options;
    options.roi_x = c.x;
    options.roi_y = c.y;
    options.roi_width = c.width;
    options.roi_height = c.height;
    options.downscale = c.downscale;
    EXPECT_EQ(laserline::daemon::raw_frame_region_problem(options, format), c.problem);
    try {
      RawFrameEncoder encoder(options, format);
      ADD_FAILURE() << "accepted " << c.problem;
    } catch (const std::invalid_argument& e) {
      EXPECT_EQ(std::string(e.what()), std::string("RawFrameEncoder: ") + c.problem);
    }
  }
  // The last pixels of the frame are inside.
  RawFrameOptions corner;
  corner.roi_x = kW - 8;
  corner.roi_y = kH - 4;
  corner.roi_width = 8;
  corner.roi_height = 4;
  corner.downscale = 4;
  corner.compression = ImageCompression::kNone;
  EXPECT_EQ(laserline::daemon::raw_frame_region_problem(corner, format), "");
  const laserline::image_t m = encode(corner, test_frame());
  EXPECT_EQ(m.width, 2);
  EXPECT_EQ(m.height, 1);
  EXPECT_EQ(laserline::daemon::raw_frame_encoder_bytes(corner, format), 2u + 2u + 0u + 4096u);
}

}  // namespace
