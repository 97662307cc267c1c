// The v4l2 camera backend against the stand-in device of tests/v4l2_fuse_device.cpp: a FUSE file
// answering the V4L2 ioctls and serving frames through mmap, run as a separate process. Checks
// the content of every frame (the stand-in draws a known pattern per sequence number), the
// timestamps, the three pixel formats, clear errors, and reconnection when the device goes away
// and comes back.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <opencv2/videoio.hpp>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "hal/clock.hpp"
#include "hal/v4l2_camera.hpp"
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
  StandIn(const std::string& format, int width, int height, int fps) {
    mountpoint_ = g_dir / "dev";
    std::filesystem::create_directories(mountpoint_);
    static int count = 0;
    output_ = g_dir / ("stand-in" + std::to_string(++count) + ".out");
    pid_ = fork();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (freopen(output_.c_str(), "w", stdout) == nullptr) _exit(126);
      dup2(fileno(stdout), 2);
      const std::string w = std::to_string(width), h = std::to_string(height),
                        f = std::to_string(fps);
      execl(V4L2_FUSE_DEVICE_PATH, V4L2_FUSE_DEVICE_PATH, mountpoint_.c_str(), "--format",
            format.c_str(), "--width", w.c_str(), "--height", h.c_str(), "--fps", f.c_str(),
            static_cast<char*>(nullptr));
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

class V4l2Test : public ::testing::TestWithParam<const char*> {};

TEST_P(V4l2Test, CapturesVerifiedFramesWithMonotonicTimestamps) {
  const std::string format = GetParam();
  constexpr int kWidth = 320, kHeight = 240;
  StandIn device(format, kWidth, kHeight, 50);
  if (const std::string problem = device.wait_ready(); !problem.empty()) GTEST_SKIP() << problem;
  V4l2Camera camera(options(device.device(), format, kWidth, kHeight));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  ASSERT_EQ(camera.format().bytes(), static_cast<std::size_t>(kWidth * kHeight));
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info, last;
  int last_first = -1;
  for (int i = 0; i < 25; ++i) {
    const std::int64_t before = laserline::hal::monotonic_ns();
    ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
    const int first = check_pattern(pixels, kWidth, kHeight);
    ASSERT_GE(first, 0) << "frame " << i << " is not whole or not the stand-in's pattern";
    EXPECT_LE(info.exposure_mono_ns, info.arrival_mono_ns);
    EXPECT_LE(info.arrival_mono_ns, laserline::hal::monotonic_ns());
    if (i > 0) {
      ASSERT_GT(info.sequence, last.sequence);
      // The content belongs to the sequence number the frame carries.
      const auto step = static_cast<int>((info.sequence - last.sequence) * 3);
      EXPECT_EQ(first, (last_first + step) & 0xff) << "frame " << i;
      EXPECT_GT(info.exposure_mono_ns, last.exposure_mono_ns);
      // Stamped at exposure start by the stand-in, after the previous frame arrived or not,
      // but never before the previous exposure.
      EXPECT_GE(info.exposure_mono_ns, before - 1'000'000'000);
    }
    last = info;
    last_first = first;
  }
  EXPECT_EQ(camera.health().reconnects, 0);

  // Steady state: poll, DQBUF, copy, QBUF allocate nothing.
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

INSTANTIATE_TEST_SUITE_P(Formats, V4l2Test, ::testing::Values("GREY", "Y16", "YUYV"));

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
