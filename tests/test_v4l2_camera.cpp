// The v4l2 camera backend against the stand-in device of tests/standins/v4l2_fuse_device.cpp: a
// FUSE file answering the V4L2 ioctls and serving frames through mmap, run as a separate process.
// Checks the content of every frame (the stand-in draws a known pattern per sequence number: every
// pixel is compared with the per-pixel reference conversion of it, pixel_reference.hpp), the
// timestamps, every pixel format with a laser channel, clear errors, and reconnection when the
// device goes away and comes back.
// Over 600 lines: one backend, on one stand-in device.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <signal.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <opencv2/videoio.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include "hal/clock.hpp"
#include "hal/laser_channel.hpp"
#include "hal/v4l2_camera.hpp"
#include "pixel_reference.hpp"
#include "standins/v4l2_test_pattern.hpp"
#include "thread_allocations.hpp"

namespace {

using laserline::hal::FrameInfo;
using laserline::hal::GrabStatus;
using laserline::hal::V4l2Camera;
using laserline::hal::V4l2CameraOptions;

std::filesystem::path g_dir;

// The stand-in device, mounted on its own directory until destroyed.
class StandIn {
 public:
  StandIn(const std::string& format, int width, int height, int fps,
          const std::vector<std::string>& more = {}) {
    mountpoint_ = g_dir / "dev";
    std::filesystem::create_directories(mountpoint_);
    static int count = 0;
    output_ = g_dir / ("stand-in" + std::to_string(++count) + ".out");
    pid_ = fork();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (freopen(output_.c_str(), "w", stdout) == nullptr) _exit(126);
      dup2(fileno(stdout), 2);
      std::vector<std::string> args = {V4L2_FUSE_DEVICE_PATH,
                                       mountpoint_.string(),
                                       "--format",
                                       format,
                                       "--width",
                                       std::to_string(width),
                                       "--height",
                                       std::to_string(height),
                                       "--fps",
                                       std::to_string(fps)};
      args.insert(args.end(), more.begin(), more.end());
      std::vector<char*> argv;
      for (auto& a : args)
        argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(V4L2_FUSE_DEVICE_PATH, argv.data());
      _exit(127);
    }
  }
  ~StandIn() { remove(); }
  std::string device() const { return (mountpoint_ / "video0").string(); }
  // "" when the device is there, else why not (no FUSE here, for example).
  std::string wait_ready() const {
    for (int i = 0; i < 100; ++i) {
      std::ifstream out(output_);
      const std::string text{std::istreambuf_iterator<char>(out), std::istreambuf_iterator<char>()};
      if (text.find("ready") != std::string::npos) return "";
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) return "stand-in device exited: " + text;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return "stand-in device not ready after 5 s";
  }
  // Unplugged: SIGTERM unmounts the file system and the device node disappears.
  void remove() {
    if (pid_ <= 0) return;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
  }

 private:
  std::filesystem::path mountpoint_;
  std::filesystem::path output_;
  pid_t pid_ = -1;
};

V4l2CameraOptions options(const std::string& device, const std::string& format, int width,
                          int height) {
  V4l2CameraOptions o;
  o.device = device;
  o.pixel_format = format;
  o.width = width;
  o.height = height;
  o.frame_rate_hz = 50;
  o.buffers = 4;
  o.reconnect_min_ms = 50;
  o.reconnect_max_ms = 200;
  return o;
}

// The stand-in's pattern: luma(x, y) = (x + 2y + 3 * driver sequence) mod 256. Returns the
// frame's first luma, or -1 when any pixel breaks the pattern.
int check_pattern(const std::vector<std::uint8_t>& pixels, int width, int height) {
  const int first = pixels[0];
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      if (pixels[static_cast<std::size_t>(y * width + x)] != ((first + x + 2 * y) & 0xff))
        return -1;
    }
  }
  return first;
}

// A pixel format served by the stand-in, how the backend must read it, and the laser channel the
// backend is given (mono formats ignore it).
struct FormatCase {
  const char* name;  // the backend's pixel_format and the stand-in's --format
  std::uint32_t fourcc;
  laserline::hal::SourceFormat source;
  const char* channel;
  std::vector<std::string> stand_in_options;  // --yuv, --padding
};

using laserline::hal::PixelLayout;
using laserline::hal::YuvMatrix;
using laserline::hal::YuvRange;

const FormatCase kFormatCases[] = {
    {"GREY", V4L2_PIX_FMT_GREY, {PixelLayout::kMono, 8}, "green", {}},
    {"Y16", V4L2_PIX_FMT_Y16, {PixelLayout::kMono, 16}, "red", {}},
    // YUYV as most webcams state it (SMPTE170M, defaults: BT.601 limited range) and stated as
    // BT.709 full range.
    {"YUYV",
     V4L2_PIX_FMT_YUYV,
     {PixelLayout::kYuyv, 8, YuvMatrix::kBt601, YuvRange::kLimited},
     "red - (green + blue) / 2",
     {}},
    {"YUYV",
     V4L2_PIX_FMT_YUYV,
     {PixelLayout::kYuyv, 8, YuvMatrix::kBt709, YuvRange::kFull},
     "green",
     {"--yuv", "709-full"}},
    {"RGB24", V4L2_PIX_FMT_RGB24, {PixelLayout::kRgb, 8}, "red - (green + blue) / 2", {}},
    {"BGR24", V4L2_PIX_FMT_BGR24, {PixelLayout::kBgr, 8}, "red", {"--padding", "16"}},
    {"SRGGB8", V4L2_PIX_FMT_SRGGB8, {PixelLayout::kBayerRggb, 8}, "red", {}},
    {"SGRBG8", V4L2_PIX_FMT_SGRBG8, {PixelLayout::kBayerGrbg, 8}, "red - (green + blue) / 2", {}},
    {"SGBRG8", V4L2_PIX_FMT_SGBRG8, {PixelLayout::kBayerGbrg, 8}, "green", {"--padding", "8"}},
    {"SBGGR8", V4L2_PIX_FMT_SBGGR8, {PixelLayout::kBayerBggr, 8}, "grey", {}},
    {"SRGGB12",
     V4L2_PIX_FMT_SRGGB12,
     {PixelLayout::kBayerRggb, 12},
     "red - (green + blue) / 2",
     {}},
    {"SGRBG12", V4L2_PIX_FMT_SGRBG12, {PixelLayout::kBayerGrbg, 12}, "green", {}},
    {"SGBRG12", V4L2_PIX_FMT_SGBRG12, {PixelLayout::kBayerGbrg, 12}, "red", {}},
    {"SBGGR12", V4L2_PIX_FMT_SBGGR12, {PixelLayout::kBayerBggr, 12}, "blue", {}},
    {"SRGGB16", V4L2_PIX_FMT_SRGGB16, {PixelLayout::kBayerRggb, 16}, "red", {}},
    {"SGRBG16",
     V4L2_PIX_FMT_SGRBG16,
     {PixelLayout::kBayerGrbg, 16},
     "red - (green + blue) / 2",
     {"--padding", "4"}},
    {"SGBRG16", V4L2_PIX_FMT_SGBRG16, {PixelLayout::kBayerGbrg, 16}, "1.5*blue - 0.25*red", {}},
    {"SBGGR16", V4L2_PIX_FMT_SBGGR16, {PixelLayout::kBayerBggr, 16}, "green", {}},
};

// For gtest's messages.
void PrintTo(const FormatCase& c, std::ostream* out) {
  *out << c.name << ", channel " << c.channel;
  for (const auto& option : c.stand_in_options)
    *out << " " << option;
}

std::uint32_t padding_of(const FormatCase& c) {
  for (std::size_t i = 0; i + 1 < c.stand_in_options.size(); ++i) {
    if (c.stand_in_options[i] == "--padding") {
      return static_cast<std::uint32_t>(std::stoul(c.stand_in_options[i + 1]));
    }
  }
  return 0;
}

// "" when `pixels` is the reference conversion of the stand-in's frame at driver sequence
// `sequence`; otherwise the first pixel that is not.
std::string frame_mismatch(const FormatCase& c, const laserline::hal::LaserChannel& channel,
                           const std::vector<std::uint8_t>& pixels, int width, int height,
                           std::uint32_t sequence) {
  const std::uint32_t padding = padding_of(c);
  const std::size_t stride =
      static_cast<std::size_t>(width) * laserline::test::pattern_bytes_per_pixel(c.fourcc) +
      padding;
  std::vector<std::uint8_t> sent(stride * static_cast<std::size_t>(height));
  laserline::test::fill_pattern(c.fourcc, static_cast<std::uint32_t>(width),
                                static_cast<std::uint32_t>(height), sequence, sent.data(), padding);
  return laserline::test::compare_with_reference(
      pixels,
      laserline::test::reference_values(sent.data(), stride, width, height, c.source, channel),
      width, channel);
}

// The driver sequence (modulo 256, after which the pattern repeats) whose frame `pixels` is, or
// -1. Candidates are screened on a small window inside the frame (its reference computed alone)
// before the whole frame is compared.
int identify_frame(const FormatCase& c, const laserline::hal::LaserChannel& channel,
                   const std::vector<std::uint8_t>& pixels, int width, int height) {
  constexpr int kWindow = 6, kX0 = 40, kY0 = 20;  // even: the window keeps the mosaic's phase
  const std::size_t stride = kWindow * laserline::test::pattern_bytes_per_pixel(c.fourcc);
  std::vector<std::uint8_t> window(stride * kWindow);
  for (std::uint32_t sequence = 0; sequence < 256; ++sequence) {
    laserline::test::fill_pattern(c.fourcc, kWindow, kWindow, sequence, window.data(), 0, kX0, kY0);
    const auto reference = laserline::test::reference_values(window.data(), stride, kWindow,
                                                             kWindow, c.source, channel);
    bool close = true;  // the window's inner pixels within one of their reference values
    for (int y = 1; y < kWindow - 1 && close; ++y) {
      for (int x = 1; x < kWindow - 1 && close; ++x) {
        const double v = reference[static_cast<std::size_t>(y * kWindow + x)].value;
        const double expected = std::min(255.0, std::max(0.0, std::floor(v + 0.5)));
        close =
            std::abs(pixels[static_cast<std::size_t>((kY0 + y) * width + kX0 + x)] - expected) <= 1;
      }
    }
    if (close && frame_mismatch(c, channel, pixels, width, height, sequence).empty()) {
      return static_cast<int>(sequence);
    }
  }
  return -1;
}

class V4l2Test : public ::testing::TestWithParam<FormatCase> {};

TEST_P(V4l2Test, CapturesVerifiedFramesWithMonotonicTimestamps) {
  const FormatCase& c = GetParam();
  constexpr int kWidth = 320, kHeight = 240;
  StandIn device(c.name, kWidth, kHeight, 50, c.stand_in_options);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2CameraOptions o = options(device.device(), c.name, kWidth, kHeight);
  o.channel = laserline::hal::parse_laser_channel(c.channel);
  V4l2Camera camera(o);
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  ASSERT_EQ(camera.format().bytes(), static_cast<std::size_t>(kWidth * kHeight));
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info, first;
  int first_sequence = -1;
  for (int i = 0; i < 25; ++i) {
    const std::int64_t before = laserline::hal::monotonic_ns();
    ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
    EXPECT_LE(info.exposure_mono_ns, info.arrival_mono_ns);
    EXPECT_LE(info.arrival_mono_ns, laserline::hal::monotonic_ns());
    if (i == 0) {
      first_sequence = identify_frame(c, o.channel, pixels, kWidth, kHeight);
      ASSERT_GE(first_sequence, 0) << "frame 0 is not whole or not the stand-in's pattern";
      first = info;
    } else {
      ASSERT_GT(info.sequence, first.sequence);
      // The content belongs to the sequence number the frame carries.
      const auto sequence =
          static_cast<std::uint32_t>(first_sequence + (info.sequence - first.sequence)) & 0xff;
      ASSERT_EQ(frame_mismatch(c, o.channel, pixels, kWidth, kHeight, sequence), "")
          << "frame " << i;
      EXPECT_GT(info.exposure_mono_ns, first.exposure_mono_ns);
      // Stamped at exposure start by the stand-in, after the previous frame arrived or not,
      // but never before the previous exposure.
      EXPECT_GE(info.exposure_mono_ns, before - 1'000'000'000);
    }
  }
  EXPECT_EQ(camera.health().reconnects, 0);

  // Steady state: poll, DQBUF, convert, QBUF allocate nothing.
  {
    laserline::test::ThreadAllocationCount probe_count;
    void* volatile probe = std::malloc(64);
    std::free(probe);
    ASSERT_EQ(probe_count.count(), 1) << "the allocation counter does not count";
  }
  laserline::test::ThreadAllocationCount allocations;
  for (int i = 0; i < 10; ++i)
    ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  EXPECT_EQ(allocations.count(), 0);
}

INSTANTIATE_TEST_SUITE_P(Formats, V4l2Test, ::testing::ValuesIn(kFormatCases),
                         [](const ::testing::TestParamInfo<FormatCase>& param) {
                           return std::string(param.param.name) + "_" + std::to_string(param.index);
                         });

TEST(V4l2, MissingDeviceOrUnsupportedFormatIsAClearError) {
  {
    V4l2Camera camera(options((g_dir / "nothing").string(), "GREY", 320, 240));
    std::string error;
    EXPECT_FALSE(camera.open(&error));
    EXPECT_EQ(error, (g_dir / "nothing").string() + ": cannot open: No such file or directory");
  }
  StandIn device("GREY", 320, 240, 30);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), "YUYV", 320, 240));
  std::string error;
  EXPECT_FALSE(camera.open(&error));
  EXPECT_EQ(error, device.device() + ": asked for YUYV 320x240, the driver offers GREY 320x240");

  // Formats are named as the backend takes them, fourccs of others as they are.
  StandIn bayer("SBGGR8", 320, 240, 30);
  if (const std::string problem = bayer.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera rggb(options(bayer.device(), "SRGGB8", 320, 240));
  EXPECT_FALSE(rggb.open(&error));
  EXPECT_EQ(error, bayer.device() + ": asked for SRGGB8 320x240, the driver offers SBGGR8 320x240");

  // A size the format cannot take: said before the device is opened.
  V4l2Camera odd(options(device.device(), "YUYV", 321, 240));
  EXPECT_FALSE(odd.open(&error));
  EXPECT_EQ(error, device.device() +
                       ": pixel_format 'YUYV': YUYV needs an even width (pixels come in pairs), "
                       "got 321x240");
}

// --check-config's look at the device: its name, driver and formats, read without setting a
// format; a missing node and a format the device lacks are one line each.
TEST(V4l2, ProbeReadsTheDeviceWithoutConfiguringIt) {
  std::string found;
  std::string error;
  V4l2Camera missing(options((g_dir / "nothing").string(), "GREY", 320, 240));
  EXPECT_FALSE(missing.probe(&found, &error));
  EXPECT_EQ(error, (g_dir / "nothing").string() + ": cannot open: No such file or directory");

  StandIn device("GREY", 320, 240, 30);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), "GREY", 320, 240));
  ASSERT_TRUE(camera.probe(&found, &error)) << error;
  EXPECT_EQ(found,
            device.device() + ": V4L2 stand-in (driver laserline-fuse, fuse:0); formats GREY");
  V4l2Camera yuyv(options(device.device(), "YUYV", 320, 240));
  EXPECT_FALSE(yuyv.probe(&found, &error));
  EXPECT_EQ(error, device.device() +
                       ": V4L2 stand-in (driver laserline-fuse, fuse:0): pixel_format 'YUYV' is "
                       "not among its formats (GREY)");
  // Probing left the device as it was: it still opens and streams.
  ASSERT_TRUE(camera.open(&error)) << error;
}

laserline::hal::CameraSetting setting(const char* name, const char* value) {
  laserline::hal::CameraSetting s;
  std::snprintf(s.name, sizeof s.name, "%s", name);
  std::snprintf(s.value, sizeof s.value, "%s", value);
  s.number = std::strtod(value, nullptr);
  return s;
}

laserline::hal::SettingResult apply(V4l2Camera& camera, const laserline::hal::CameraSetting& s) {
  EXPECT_EQ(camera.check_setting(s), "") << s.name;
  laserline::hal::SettingResult result;
  camera.apply_setting(s, result);
  return result;
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Settings while streaming (laserlined's commands): controls found by name with QUERY_EXT_CTRL,
// set with S_EXT_CTRLS and read back with G_EXT_CTRLS (the stand-in's log names the ioctl that
// wrote each value); exposure_us in the absolute exposure's 100 us units, carried by the frames
// from then on; the device's range and unknown names refused in one line.
TEST(V4l2, ControlsAreSetByNameAndReadBack) {
  const std::filesystem::path log = g_dir / "controls.log";
  StandIn device("GREY", 160, 120, 50, {"--control-log", log.string()});
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), "GREY", 160, 120));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  EXPECT_TRUE(std::isnan(info.exposure_us)) << "not known before it is set";

  laserline::hal::SettingResult gain = apply(camera, setting("v4l2:gain", "50"));
  EXPECT_TRUE(gain.accepted) << gain.reason;
  EXPECT_STREQ(gain.old_value, "32");
  EXPECT_STREQ(gain.in_force, "50");
  // The driver's own name works too.
  laserline::hal::SettingResult raw = apply(camera, setting("v4l2:Exposure Time, Absolute", "30"));
  EXPECT_TRUE(raw.accepted) << raw.reason;
  EXPECT_STREQ(raw.old_value, "100");
  laserline::hal::SettingResult exposure = apply(camera, setting("exposure_us", "2000"));
  EXPECT_TRUE(exposure.accepted) << exposure.reason;
  EXPECT_STREQ(exposure.old_value, "3000");
  EXPECT_STREQ(exposure.in_force, "2000");
  ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  EXPECT_EQ(info.exposure_us, 2000);
  const std::string written =
      "S_EXT_CTRLS 0x00980913 50\n"
      "S_EXT_CTRLS 0x009a0902 30\n"
      "S_EXT_CTRLS 0x009a0902 20\n";
  EXPECT_EQ(read_text(log), written);

  laserline::hal::SettingResult too_high = apply(camera, setting("v4l2:gain", "300"));
  EXPECT_FALSE(too_high.accepted);
  EXPECT_STREQ(too_high.reason,
               "v4l2:gain: must be between 0 and 255 (the device's range), got 300");
  laserline::hal::SettingResult too_long = apply(camera, setting("exposure_us", "1000100"));
  EXPECT_FALSE(too_long.accepted);
  EXPECT_STREQ(too_long.reason,
               "exposure_us: must be between 100 and 1000000 (the device's range), got 1000100");
  laserline::hal::SettingResult missing = apply(camera, setting("v4l2:brightness", "3"));
  EXPECT_FALSE(missing.accepted);
  EXPECT_STREQ(missing.reason,
               "v4l2:brightness: the device has no such control (integer, boolean or menu)");
  EXPECT_EQ(camera.check_setting(setting("gain_db", "3")),
            "gain_db: V4L2's gain has no unit; set the driver's control, e.g. v4l2:gain");
  EXPECT_EQ(camera.check_setting(setting("v4l2:gain", "2.5")),
            "v4l2:gain: must be a whole number (the control's value, a menu's index; at most "
            "2^53 in size), got '2.5'");
  char value[64];
  ASSERT_TRUE(camera.read_setting("v4l2:gain", value));
  EXPECT_STREQ(value, "50");
  EXPECT_EQ(read_text(log), written) << "refused settings reached the device";
}

// 64-bit controls (their range only QUERY_EXT_CTRL states; G/S_CTRL cannot carry them), a
// read-only control, and the driver's own refusal (a flip grabbed while streaming) in one line.
TEST(V4l2, SixtyFourBitControlsAndTheDriversRefusals) {
  StandIn device("GREY", 160, 120, 50);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), "GREY", 160, 120));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);

  char value[64];
  ASSERT_TRUE(camera.read_setting("v4l2:pixel_rate", value));
  EXPECT_STREQ(value, "8000000000");
  laserline::hal::SettingResult wide =
      apply(camera, setting("v4l2:integer_64_bits", "-5000000001"));
  EXPECT_TRUE(wide.accepted) << wide.reason;
  EXPECT_STREQ(wide.old_value, "0");
  EXPECT_STREQ(wide.in_force, "-5000000001");
  laserline::hal::SettingResult beyond =
      apply(camera, setting("v4l2:integer_64_bits", "2000000000000"));
  EXPECT_FALSE(beyond.accepted);
  EXPECT_STREQ(beyond.reason,
               "v4l2:integer_64_bits: must be between -1099511627776 and 1099511627776 (the "
               "device's range), got 2000000000000");
  laserline::hal::SettingResult read_only = apply(camera, setting("v4l2:pixel_rate", "1000"));
  EXPECT_FALSE(read_only.accepted);
  EXPECT_STREQ(read_only.reason, "v4l2:pixel_rate: the control is read-only");
  laserline::hal::SettingResult grabbed = apply(camera, setting("v4l2:horizontal_flip", "1"));
  EXPECT_FALSE(grabbed.accepted);
  EXPECT_STREQ(grabbed.reason,
               "v4l2:horizontal_flip: the driver refused it before changing anything "
               "(VIDIOC_S_EXT_CTRLS: Device or resource busy)");
  ASSERT_TRUE(camera.read_setting("v4l2:horizontal_flip", value));
  EXPECT_STREQ(value, "0");
  EXPECT_EQ(camera.check_setting(setting("v4l2:integer_64_bits", "1e16")),
            "v4l2:integer_64_bits: must be a whole number (the control's value, a menu's index; "
            "at most 2^53 in size), got '1e16'");
}

// A value the driver took but could not write to the sensor (EIO, error_idx naming the control)
// is told apart from a request refused before any change.
TEST(V4l2, AFailedWriteIsToldApartFromARefusal) {
  StandIn device("GREY", 160, 120, 50, {"--control-writes", "fail"});
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), "GREY", 160, 120));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  laserline::hal::SettingResult gain = apply(camera, setting("v4l2:gain", "40"));
  EXPECT_FALSE(gain.accepted);
  EXPECT_STREQ(gain.reason,
               "v4l2:gain: the driver failed while setting it (VIDIOC_S_EXT_CTRLS: Input/output "
               "error)");
}

// The stand-in answers an extended-control request as the kernel's control framework does, for a
// client that calls ioctl() itself: S_EXT_CTRLS checks every control before changing any
// (error_idx = count when it refuses), TRY names the control it refuses, integers are clamped
// to their range and the values in force are written back into the caller's array.
TEST(V4l2, StandInAnswersExtendedControlsAsTheKernel) {
  StandIn device("GREY", 160, 120, 50);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  const int fd = open(device.device().c_str(), O_RDWR);
  ASSERT_GE(fd, 0);
  v4l2_ext_control controls[2] = {};
  v4l2_ext_controls request{};
  request.which = V4L2_CTRL_WHICH_CUR_VAL;
  request.count = 2;
  request.controls = controls;
  auto run = [&](unsigned long cmd, std::uint32_t first, std::int32_t first_value,
                 std::uint32_t second, std::int32_t second_value) {
    controls[0] = {};
    controls[0].id = first;
    controls[0].value = first_value;
    controls[1] = {};
    controls[1].id = second;
    controls[1].value = second_value;
    request.error_idx = 99;
    return ioctl(fd, cmd, &request) == 0 ? 0 : errno;
  };
  constexpr std::uint32_t kUnknown = V4L2_CID_USER_BASE + 0x999;
  EXPECT_EQ(run(VIDIOC_S_EXT_CTRLS, V4L2_CID_GAIN, 60, kUnknown, 1), EINVAL);
  EXPECT_EQ(request.error_idx, 2u) << "refused before any control was changed";
  EXPECT_EQ(run(VIDIOC_TRY_EXT_CTRLS, V4L2_CID_GAIN, 60, kUnknown, 1), EINVAL);
  EXPECT_EQ(request.error_idx, 1u) << "TRY names the control it refuses";
  EXPECT_EQ(run(VIDIOC_G_EXT_CTRLS, V4L2_CID_GAIN, 0, V4L2_CID_EXPOSURE_ABSOLUTE, 0), 0);
  EXPECT_EQ(controls[0].value, 32) << "the gain was not changed by the refused request";
  EXPECT_EQ(controls[1].value, 100);

  EXPECT_EQ(run(VIDIOC_S_EXT_CTRLS, V4L2_CID_GAIN, 400, V4L2_CID_EXPOSURE_ABSOLUTE, 20), 0);
  EXPECT_EQ(controls[0].value, 255) << "clamped to the range, written back";
  EXPECT_EQ(controls[1].value, 20);
  EXPECT_EQ(run(VIDIOC_G_EXT_CTRLS, V4L2_CID_GAIN, 0, V4L2_CID_EXPOSURE_ABSOLUTE, 0), 0);
  EXPECT_EQ(controls[0].value, 255);
  EXPECT_EQ(controls[1].value, 20);

  // A control class for `which`: every control must be of that class.
  request.which = V4L2_CTRL_CLASS_USER;
  EXPECT_EQ(run(VIDIOC_TRY_EXT_CTRLS, V4L2_CID_GAIN, 1, V4L2_CID_EXPOSURE_ABSOLUTE, 1), EINVAL);
  EXPECT_EQ(request.error_idx, 1u);
  EXPECT_EQ(run(VIDIOC_S_EXT_CTRLS, V4L2_CID_GAIN, 1, V4L2_CID_EXPOSURE_ABSOLUTE, 1), EINVAL);
  EXPECT_EQ(request.error_idx, 2u);
  close(fd);
}

// A driver without the extended-control ioctls (ENOTTY, as before the control framework): its
// 32-bit controls are found with QUERYCTRL, set with S_CTRL and read back with G_CTRL.
TEST(V4l2, DriversWithoutExtendedControlsGetTheOldIoctls) {
  const std::filesystem::path log = g_dir / "legacy.log";
  StandIn device("GREY", 160, 120, 50, {"--controls", "legacy", "--control-log", log.string()});
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), "GREY", 160, 120));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  laserline::hal::SettingResult gain = apply(camera, setting("v4l2:gain", "70"));
  EXPECT_TRUE(gain.accepted) << gain.reason;
  EXPECT_STREQ(gain.old_value, "32");
  EXPECT_STREQ(gain.in_force, "70");
  laserline::hal::SettingResult exposure = apply(camera, setting("exposure_us", "1500"));
  EXPECT_TRUE(exposure.accepted) << exposure.reason;
  EXPECT_STREQ(exposure.in_force, "1500");
  laserline::hal::SettingResult too_high = apply(camera, setting("v4l2:gain", "256"));
  EXPECT_STREQ(too_high.reason,
               "v4l2:gain: must be between 0 and 255 (the device's range), got 256");
  EXPECT_EQ(read_text(log), "S_CTRL 0x00980913 70\nS_CTRL 0x009a0902 15\n");
}

TEST(V4l2, ReconnectsWhenTheDeviceDisappearsAndReturns) {
  auto device = std::make_unique<StandIn>("GREY", 160, 120, 50);
  if (const std::string problem = device->wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device->device(), "GREY", 160, 120));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  const std::uint64_t before_unplug = info.sequence;

  device->remove();
  GrabStatus status = camera.grab(pixels, info, std::chrono::milliseconds(500));
  EXPECT_EQ(status, GrabStatus::kError) << laserline::hal::to_string(status);
  // Gone: grabs fail (reconnect attempts) or time out, never deliver.
  for (int i = 0; i < 5; ++i) {
    status = camera.grab(pixels, info, std::chrono::milliseconds(100));
    EXPECT_NE(status, GrabStatus::kOk);
  }

  device = std::make_unique<StandIn>("GREY", 160, 120, 50);
  ASSERT_EQ(device->wait_ready(), "");
  status = GrabStatus::kError;
  for (int i = 0; i < 50 && status != GrabStatus::kOk; ++i)
    status = camera.grab(pixels, info, std::chrono::milliseconds(200));
  ASSERT_EQ(status, GrabStatus::kOk);
  EXPECT_GE(check_pattern(pixels, 160, 120), 0);
  EXPECT_GT(info.sequence, before_unplug) << "sequence numbers continue across the reconnect";
  EXPECT_EQ(camera.health().reconnects, 1);
}

// OpenCV's own V4L2 capture runs against the stand-in too (it opens the device blocking and waits
// in DQBUF, where this backend polls): the stand-in is not shaped around one client.
TEST(V4l2, OpenCvCapturesFromTheStandIn) {
  StandIn device("GREY", 320, 240, 30);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  cv::VideoCapture capture(device.device(), cv::CAP_V4L2);
  ASSERT_TRUE(capture.isOpened());
  capture.set(cv::CAP_PROP_CONVERT_RGB, 0);
  int last_first = -1;
  for (int i = 0; i < 5; ++i) {
    cv::Mat frame;
    ASSERT_TRUE(capture.read(frame)) << "frame " << i;
    ASSERT_EQ(frame.type(), CV_8UC1);
    ASSERT_EQ(frame.cols, 320);
    ASSERT_EQ(frame.rows, 240);
    const std::vector<std::uint8_t> pixels(frame.data, frame.data + frame.total());
    const int first = check_pattern(pixels, 320, 240);
    EXPECT_GE(first, 0) << "frame " << i << " is not whole";
    EXPECT_NE(first, last_first) << "frame " << i << " repeats the previous one";
    last_first = first;
  }
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  g_dir = std::filesystem::temp_directory_path() / ("laserline_v4l2_" + std::to_string(getpid()));
  std::filesystem::create_directories(g_dir);
  const int result = RUN_ALL_TESTS();
  std::filesystem::remove_all(g_dir);
  return result;
}
