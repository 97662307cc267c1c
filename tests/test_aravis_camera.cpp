// The aravis camera backend against Aravis's own fake GigE Vision camera
// (arv-fake-gv-camera-0.8 -i 127.0.0.1), over the real GVCP/GVSP network path on loopback, inside
// a private network namespace this test makes for itself (discovery would otherwise broadcast on
// the machine's interfaces). The daemon tests run laserlined as a separate process with the
// stand-in GPIO chip (tests/standins/gpiochip_shim.cpp) preloaded, so the laser's pin is logged.
// Over 600 lines: one backend, on one stand-in camera and network namespace.
#include <arv.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "hal/aravis_camera.hpp"
#include "hal/clock.hpp"
#include "hal/laser_channel.hpp"
#include "pixel_reference.hpp"
#include "private_network.hpp"
#include "run_command.hpp"
#include "thread_allocations.hpp"

namespace {

using laserline::hal::AravisCamera;
using laserline::hal::AravisCameraOptions;
using laserline::hal::FrameInfo;
using laserline::hal::GrabStatus;

std::string g_namespace_problem = "not tried";
std::filesystem::path g_dir;

#ifdef LASERLINE_SANITIZED
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

pid_t spawn(const std::vector<std::string>& args, const std::vector<std::string>& env,
            const std::filesystem::path& output) {
  const pid_t pid = fork();
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);  // no orphan when the test is killed
    if (freopen(output.c_str(), "w", stdout) == nullptr) _exit(126);
    dup2(fileno(stdout), 2);
    for (const auto& e : env)
      putenv(const_cast<char*>(e.c_str()));
    std::vector<char*> argv;
    for (const auto& a : args)
      argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execvp(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}

int wait_exit(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The fake camera, running until destroyed. Ready once Aravis discovers it.
class FakeCamera {
 public:
  explicit FakeCamera(const std::string& lost_per_thousand = "") {
    std::vector<std::string> args = {"arv-fake-gv-camera-0.8", "-i", "127.0.0.1"};
    if (!lost_per_thousand.empty()) {
      args.push_back("-r");
      args.push_back(lost_per_thousand);
    }
    pid_ = spawn(args, {}, g_dir / "fake-camera.out");
  }
  ~FakeCamera() { kill(); }
  bool wait_ready() const {
    for (int i = 0; i < 100; ++i) {
      arv_update_device_list();
      if (arv_get_n_devices() > 0) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }
  void kill() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      wait_exit(pid_);
      pid_ = -1;
    }
  }

 private:
  pid_t pid_ = -1;
};

AravisCameraOptions options(int width, int height, double rate) {
  AravisCameraOptions o;
  o.device = "127.0.0.1";
  o.width = width;
  o.height = height;
  o.frame_rate_hz = rate;
  o.packet_size = 1400;
  o.buffers = 8;
  return o;
}

class AravisTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!g_namespace_problem.empty()) {
      GTEST_SKIP() << "no private network namespace for the fake GigE camera: "
                   << g_namespace_problem;
    }
  }
};

TEST_F(AravisTest, StreamsWholeFramesWithBothTimestamps) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCamera camera(options(640, 480, 50));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  std::vector<std::uint8_t> previous;
  FrameInfo info;
  FrameInfo last;
  int frames = 0;
  while (frames < 40) {
    const std::int64_t before = laserline::hal::monotonic_ns();
    const GrabStatus status = camera.grab(pixels, info, std::chrono::milliseconds(1000));
    ASSERT_EQ(status, GrabStatus::kOk) << laserline::hal::to_string(status);
    EXPECT_GE(info.arrival_mono_ns, before);
    EXPECT_LE(info.arrival_mono_ns, laserline::hal::monotonic_ns());
    EXPECT_LE(info.exposure_mono_ns, info.arrival_mono_ns) << "exposure after arrival";
    if (frames > 0) {
      EXPECT_EQ(info.sequence, last.sequence + 1) << "a frame was lost on loopback";
      EXPECT_GT(info.camera_ns, last.camera_ns);
      EXPECT_GT(info.exposure_mono_ns, last.exposure_mono_ns);
      // The fake camera draws a pattern that moves with every frame.
      EXPECT_NE(pixels, previous) << "frame " << frames << " repeats the previous one";
    }
    EXPECT_NE(std::count(pixels.begin(), pixels.end(), 0), static_cast<long>(pixels.size()));
    previous = pixels;
    last = info;
    ++frames;
  }
  const laserline::hal::CameraHealth health = camera.health();
  EXPECT_EQ(health.missing_packets, 0);
  EXPECT_EQ(health.underruns, 0);
  EXPECT_EQ(health.reconnects, 0);

  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    camera.stop();
  });
  GrabStatus status = GrabStatus::kOk;
  while (status == GrabStatus::kOk)
    status = camera.grab(pixels, info, std::chrono::milliseconds(5000));
  stopper.join();
  EXPECT_EQ(status, GrabStatus::kStopped);
}

// The frame path's side of the camera (pop, copy, push back, statistics) allocates nothing.
// Aravis's own receiving thread is not ours and is not counted: it allocates about two blocks per
// frame for its bookkeeping (measured while writing this test).
TEST_F(AravisTest, GrabbingAllocatesNothingOnTheCallingThread) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCamera camera(options(640, 480, 100));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  for (int i = 0; i < 10; ++i)
    ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  {
    // The counter must count, or a zero would prove nothing.
    laserline::test::ThreadAllocationCount probe_count;
    void* volatile probe = std::malloc(64);
    std::free(probe);
    ASSERT_EQ(probe_count.count(), 1);
  }
  int frames = 0;
  laserline::test::ThreadAllocationCount allocations;
  for (int i = 0; i < 100; ++i)
    frames += camera.grab(pixels, info, std::chrono::milliseconds(1000)) == GrabStatus::kOk;
  EXPECT_EQ(frames, 100);
  EXPECT_EQ(allocations.count(), 0);
}

// With the software trigger the daemon owns the exposure clock: each grab() triggers exactly one
// exposure (after the laser was set), and no frame comes without one.
TEST_F(AravisTest, SoftwareTriggerGivesOneFramePerGrab) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCameraOptions o = options(320, 240, 30);
  o.trigger = laserline::hal::AravisTrigger::kSoftware;
  AravisCamera camera(o);
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  std::uint64_t last = 0;
  std::int64_t last_camera_ns = 0;
  for (int i = 0; i < 10; ++i) {
    ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(2000)), GrabStatus::kOk);
    if (i > 0) {
      EXPECT_EQ(info.sequence, last + 1);
    }
    if (i == 6) {
      // Exposed when grab() asked, after the idle time: not a frame queued during it.
      EXPECT_GE(info.camera_ns - last_camera_ns, 300'000'000);
    }
    last = info.sequence;
    last_camera_ns = info.camera_ns;
    // Idle: a free-running camera would deliver several frames meanwhile; a triggered one none.
    std::this_thread::sleep_for(std::chrono::milliseconds(i == 5 ? 300 : 0));
  }
  EXPECT_EQ(camera.health().reconnects, 0);
}

TEST_F(AravisTest, OpensByDeviceIdSerialNumberOrAddress) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  for (const char* name : {"Aravis-Fake-GV01", "GV01", "127.0.0.1", ""}) {
    AravisCameraOptions o = options(320, 240, 30);
    o.device = name;
    AravisCamera camera(o);
    std::string error;
    EXPECT_TRUE(camera.open(&error)) << "'" << name << "': " << error;
  }
}

TEST_F(AravisTest, MissingCameraOrImpossibleFormatIsAClearError) {
  {
    AravisCamera camera(options(640, 480, 30));
    std::string error;
    EXPECT_FALSE(camera.open(&error));
    EXPECT_EQ(error.rfind("device '127.0.0.1': ", 0), 0u) << error;
  }
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCameraOptions o = options(640, 480, 30);
  o.pixel_format = "Mono12";  // the fake camera has Mono8 and Mono16 only
  AravisCamera camera(o);
  std::string error;
  EXPECT_FALSE(camera.open(&error));
  EXPECT_EQ(error.rfind("device '127.0.0.1': pixel_format 'Mono12': ", 0), 0u) << error;
}

// Each frame carries the exposure and gain the camera was set to (read back from it once after
// configuring: what the camera took, not what was asked for).
TEST_F(AravisTest, FramesCarryTheCamerasExposureAndGain) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCameraOptions o = options(320, 240, 50);
  o.exposure_us = 2500;
  o.gain_db = 3;
  AravisCamera camera(o);
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  EXPECT_DOUBLE_EQ(info.exposure_us, 2500);
  EXPECT_DOUBLE_EQ(info.gain_db, 3);
}

TEST_F(AravisTest, Mono16IsDeliveredAsItsTopByte) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCameraOptions o = options(320, 240, 50);
  o.pixel_format = "Mono16";
  AravisCamera camera(o);
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
  EXPECT_EQ(camera.format().stride, 320);
  EXPECT_NE(std::count(pixels.begin(), pixels.end(), 0), static_cast<long>(pixels.size()));
}

TEST_F(AravisTest, PacketLossIsCountedAndSurvived) {
  FakeCamera fake("20");  // 2 % of the stream packets dropped by the camera
  ASSERT_TRUE(fake.wait_ready());
  // 320x240 in 1400-byte packets: 55 packets a frame, so about a third of the frames lose none.
  AravisCamera camera(options(320, 240, 100));
  std::string error;
  ASSERT_TRUE(camera.open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  FrameInfo info;
  int whole = 0;
  int timeouts = 0;
  std::int64_t first = -1, gaps = 0;  // frames the sequence numbers skipped
  for (int i = 0; i < 40 && whole < 20; ++i) {
    const GrabStatus status = camera.grab(pixels, info, std::chrono::milliseconds(500));
    whole += status == GrabStatus::kOk;
    timeouts += status == GrabStatus::kTimeout;
    ASSERT_NE(status, GrabStatus::kError) << "packet loss must not be taken for a lost camera";
    if (status != GrabStatus::kOk) continue;
    const auto sequence = static_cast<std::int64_t>(info.sequence);
    if (first >= 0) gaps = sequence - first - (whole - 1);
    if (first < 0) first = sequence;
  }
  const auto health = camera.health();
  std::printf(
      "-r 20 at 320x240: %d whole frames, %lld incomplete (missing packets), %lld driver "
      "timeouts, %lld skipped in the camera's numbering, %d grab timeouts, %lld reconnects\n",
      whole, static_cast<long long>(health.missing_packets),
      static_cast<long long>(health.timeouts), static_cast<long long>(health.skipped_frames),
      timeouts, static_cast<long long>(health.reconnects));
  EXPECT_EQ(whole, 20);
  EXPECT_GT(health.missing_packets + health.timeouts, 0) << "no loss was counted";
  // Every frame the camera numbered between the first and last whole one and that did not arrive
  // whole is counted, whatever happened to it.
  EXPECT_EQ(health.skipped_frames, gaps);
  EXPECT_GT(health.skipped_frames, 0);
  EXPECT_EQ(health.reconnects, 0);
}

// ---- colour ----------------------------------------------------------------------------------
//
// The fake camera's fill pattern (arv_fake_camera_diagonal_ramp in Aravis 0.8.26's
// arvfakecamera.c, at its default gain and exposure): pixel (x, y) of the frame with id f has the
// colour map's entry (x + y + f) % 255; Mono8 sends that index, RGB8 the entry's red, green and
// blue, and the Bayer formats one of them per site. The colour map (a "jet" ramp) is not public:
// it is read from one RGB8 frame taken with plain Aravis, and the whole model is checked against
// raw frames before our backend's output is checked against the model.

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
};
using ColourMap = std::array<Rgb, 255>;

// One frame taken with plain Aravis (none of our code).
struct RawFrame {
  std::vector<std::uint8_t> pixels;
  std::uint64_t frame_id = 0;
};

std::string grab_raw(const char* pixel_format, int width, int height, RawFrame& out) {
  GError* e = nullptr;
  ArvCamera* camera = arv_camera_new("127.0.0.1", &e);
  auto failed = [&](const char* what) {
    if (e == nullptr) return std::string();
    const std::string message = std::string(what) + ": " + e->message;
    g_clear_error(&e);
    return message;
  };
  if (camera == nullptr) return failed("arv_camera_new");
  std::string problem;
  arv_camera_set_pixel_format_from_string(camera, pixel_format, &e);
  problem = failed("pixel format");
  if (problem.empty()) {
    arv_camera_set_region(camera, 0, 0, width, height, &e);
    problem = failed("region");
  }
  if (problem.empty()) {
    ArvBuffer* buffer = arv_camera_acquisition(camera, 2'000'000, &e);
    problem = failed("acquisition");
    if (problem.empty() &&
        (buffer == nullptr || arv_buffer_get_status(buffer) != ARV_BUFFER_STATUS_SUCCESS)) {
      problem = "acquisition: no whole frame";
    }
    if (problem.empty()) {
      std::size_t size = 0;
      const auto* data = static_cast<const std::uint8_t*>(arv_buffer_get_data(buffer, &size));
      out.pixels.assign(data, data + size);
      out.frame_id = arv_buffer_get_frame_id(buffer);
    }
    if (buffer != nullptr) g_object_unref(buffer);
  }
  g_object_unref(camera);
  return problem;
}

// The colours of the mosaic's sites the fake camera draws for a Bayer format, its top-left 2x2
// cell row by row. BayerGR8 and BayerGB8 are drawn as named; BayerRG8 and BayerBG8 are drawn the
// other way round (arvfakecamera.c puts blue at (0, 0) for BayerRG8 and red for BayerBG8, against
// its own comments and the GenICam names). A camera that draws them as named gives the same
// checks; our backend reads every format by its GenICam name.
const char* fake_camera_mosaic(const std::string& format) {
  if (format == "BayerRG8") return "BGGR";
  if (format == "BayerBG8") return "RGGB";
  if (format == "BayerGR8") return "GRBG";
  if (format == "BayerGB8") return "GBRG";
  return nullptr;
}

// The buffer the fake camera sends for frame id f.
std::vector<std::uint8_t> fake_camera_frame(const std::string& format, const ColourMap& map,
                                            int width, int height, std::uint64_t f) {
  std::vector<std::uint8_t> frame;
  const char* mosaic = fake_camera_mosaic(format);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const auto index = static_cast<std::size_t>((static_cast<std::uint64_t>(x + y) + f) % 255);
      const Rgb& c = map[index];
      if (format == "Mono8") {
        frame.push_back(static_cast<std::uint8_t>(index));
      } else if (format == "RGB8") {
        frame.insert(frame.end(), {c.r, c.g, c.b});
      } else {
        const char site = mosaic[2 * (y % 2) + (x % 2)];
        frame.push_back(site == 'R' ? c.r : site == 'G' ? c.g : c.b);
      }
    }
  }
  return frame;
}

// Reads the colour map from an RGB8 frame 255 pixels wide or more.
std::string learn_colour_map(ColourMap& map) {
  RawFrame raw;
  if (std::string problem = grab_raw("RGB8", 256, 2, raw); !problem.empty()) return problem;
  if (raw.pixels.size() != 256 * 2 * 3) return "RGB8 frame of the wrong size";
  for (int x = 0; x < 255; ++x) {
    const std::uint8_t* p = &raw.pixels[static_cast<std::size_t>(3 * x)];
    map[(static_cast<std::uint64_t>(x) + raw.frame_id) % 255] = {p[0], p[1], p[2]};
  }
  return "";
}

class AravisColourTest : public AravisTest {
 protected:
  void SetUp() override {
    AravisTest::SetUp();
    if (IsSkipped()) return;
    fake_ = std::make_unique<FakeCamera>();
    ASSERT_TRUE(fake_->wait_ready());
    ASSERT_EQ(learn_colour_map(map_), "");
  }

  std::unique_ptr<FakeCamera> fake_;
  ColourMap map_;
};

// The model above is the fake camera's pattern: raw frames of every format it serves, taken with
// plain Aravis, are exactly the model's frames for their ids.
TEST_F(AravisColourTest, FakeCameraFillPatternIsKnown) {
  std::set<int> colours;
  for (const Rgb& c : map_)
    colours.insert(c.r << 16 | c.g << 8 | c.b);
  EXPECT_GT(colours.size(), 200u) << "the colour map is not a colour ramp";
  for (const char* format : {"Mono8", "RGB8", "BayerRG8", "BayerGR8", "BayerGB8", "BayerBG8"}) {
    RawFrame raw;
    ASSERT_EQ(grab_raw(format, 64, 48, raw), "") << format;
    EXPECT_EQ(raw.pixels, fake_camera_frame(format, map_, 64, 48, raw.frame_id)) << format;
  }
}

// Every pixel our backend delivers is the per-pixel reference conversion (pixel_reference.hpp)
// of the frame the fake camera sent: the Bayer formats, RGB8, and Mono8 (taken as it is, whatever
// the channel), over the real GigE path.
TEST_F(AravisColourTest, ColourFormatsAreConvertedByTheLasersChannel) {
  // x + y spans 0..254: every frame shows the whole colour map once, so that only its own id
  // explains it.
  constexpr int kWidth = 128, kHeight = 127;
  const std::pair<const char*, laserline::hal::SourceFormat> formats[] = {
      {"Mono8", {laserline::hal::PixelLayout::kMono, 8}},
      {"RGB8", {laserline::hal::PixelLayout::kRgb, 8}},
      {"BayerRG8", {laserline::hal::PixelLayout::kBayerRggb, 8}},
      {"BayerGR8", {laserline::hal::PixelLayout::kBayerGrbg, 8}},
      {"BayerGB8", {laserline::hal::PixelLayout::kBayerGbrg, 8}},
      {"BayerBG8", {laserline::hal::PixelLayout::kBayerBggr, 8}},
  };
  for (const auto& [format, source] : formats) {
    for (const char* channel_text : {"red", "red - (green + blue) / 2"}) {
      SCOPED_TRACE(std::string(format) + ", channel " + channel_text);
      AravisCameraOptions o = options(kWidth, kHeight, 50);
      o.pixel_format = format;
      o.channel = laserline::hal::parse_laser_channel(channel_text);
      AravisCamera camera(o);
      std::string error;
      ASSERT_TRUE(camera.open(&error)) << error;
      std::vector<std::uint8_t> pixels(camera.format().bytes());
      FrameInfo info;
      // The frame id is not delivered: the first frame's is found among the 255 the pattern
      // repeats over, the next ones' follow from their sequence numbers.
      std::uint64_t first_id = 0, first_sequence = 0;
      for (int i = 0; i < 3; ++i) {
        ASSERT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), GrabStatus::kOk);
        auto check = [&](std::uint64_t id) {
          const auto sent = fake_camera_frame(format, map_, kWidth, kHeight, id);
          return laserline::test::compare_with_reference(
              pixels,
              laserline::test::reference_values(sent.data(), sent.size() / kHeight, kWidth, kHeight,
                                                source, o.channel),
              kWidth, o.channel);
        };
        if (i == 0) {
          int matches = 0;
          for (std::uint64_t id = 0; id < 255; ++id) {
            if (check(id).empty()) {
              first_id = id;
              ++matches;
            }
          }
          ASSERT_EQ(matches, 1) << "frame ids whose frame the output is";
          first_sequence = info.sequence;
        } else {
          EXPECT_EQ(check(first_id + (info.sequence - first_sequence)), "") << "frame " << i;
        }
      }
      const std::set<std::uint8_t> values(pixels.begin(), pixels.end());
      EXPECT_GT(values.size(), 20u) << "a flat frame would prove little";
    }
  }
}

TEST_F(AravisColourTest, FormatsTheFakeCameraLacksAreClearErrors) {
  // BGR8: "BGR8" and the older "BGR8Packed" are both refused; the first refusal is reported.
  for (const char* format : {"BGR8", "BayerRG16", "BayerGB12"}) {
    AravisCameraOptions o = options(64, 48, 30);
    o.pixel_format = format;
    AravisCamera camera(o);
    std::string error;
    EXPECT_FALSE(camera.open(&error));
    EXPECT_EQ(error.rfind("device '127.0.0.1': pixel_format '" + std::string(format) + "': ", 0),
              0u)
        << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  }
  // A mosaic needs 2x2 pixels: said before the camera is touched.
  AravisCameraOptions o = options(1, 48, 30);
  o.pixel_format = "BayerRG8";
  AravisCamera camera(o);
  std::string error;
  EXPECT_FALSE(camera.open(&error));
  EXPECT_EQ(error, "pixel_format 'BayerRG8': a Bayer mosaic needs at least 2x2 pixels, got 1x48");
}

// ---- laserlined ------------------------------------------------------------------------------

struct DaemonRun {
  pid_t pid = -1;
  std::filesystem::path output;
  std::filesystem::path pins;
  std::filesystem::path lcm_log;
};

// The fake camera at 1280x1024 and its full rate; `lost_after_ms` as given.
std::string fake_camera_at_1280(int lost_after_ms) {
  return "camera: {backend: aravis, device: \"127.0.0.1\", frame_rate_hz: 1000, packet_size: 1400,"
         " timeout_ms: 200, lost_after_ms: " +
         std::to_string(lost_after_ms) +
         "}\n"
         "calibration: {camera: {width: 1280, height: 1024, fx: 1400, fy: 1400}}\n";
}

DaemonRun start_daemon(const std::string& name, const std::string& camera_and_calibration,
                       const std::string& laser_mode, double seconds) {
  DaemonRun run;
  run.output = g_dir / (name + ".out");
  run.pins = g_dir / (name + ".pins");
  run.lcm_log = g_dir / (name + ".lcm");
  const auto config = g_dir / (name + ".yaml");
  std::ofstream(config) << camera_and_calibration
                        << "laser: {backend: gpiod, chip: gpiochip0, line: 0, mode: " << laser_mode
                        << "}\npipeline: {frame_slots: 64}\nlcm: {url: \"file://"
                        << run.lcm_log.string()
                        << "?mode=w\", image_every_n: 0, status_period_s: 0.5}\n";
  run.pid =
      spawn({LASERLINED_PATH, "--config", config.string(), "--duration", std::to_string(seconds)},
            {std::string("LD_PRELOAD=") + GPIOCHIP_SHIM_PATH,
             "LASERLINE_GPIO_SHIM_LOG=" + run.pins.string(), "LASERLINE_GPIO_SHIM_LINES=LASER",
             "ASAN_OPTIONS=verify_asan_link_order=0"},
            run.output);
  return run;
}

std::vector<laserline::status_t> statuses(const std::filesystem::path& lcm_log) {
  std::vector<laserline::status_t> out;
  lcm::LogFile log(lcm_log.string(), "r");
  if (!log.good()) return out;
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    if (event->channel != "LASERLINE_STATUS") continue;
    laserline::status_t s;
    if (s.decode(event->data, 0, static_cast<int>(event->datalen)) > 0) out.push_back(s);
  }
  return out;
}

struct PinEvent {
  std::int64_t mono_ns = 0;
  int level = 0;
  std::string event;
};

std::vector<PinEvent> pin_events(const std::filesystem::path& path) {
  std::vector<PinEvent> events;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    PinEvent e;
    std::int64_t wall = 0;
    unsigned offset = 0;
    fields >> e.mono_ns >> wall >> offset >> e.level >> e.event;
    events.push_back(e);
  }
  return events;
}

TEST_F(AravisTest, DaemonSixtySecondsAtTheFakeCamerasRate) {
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  DaemonRun run = start_daemon("sixty", fake_camera_at_1280(1000), "alternate", 60);
  const int status = wait_exit(run.pid);
  const std::string out = read_text(run.output);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  const auto all = statuses(run.lcm_log);
  ASSERT_FALSE(all.empty()) << out;
  const laserline::status_t& s = all.back();
  std::printf(
      "60 s at 1280x1024: %lld frames in (%.1f Hz), %lld processed, %lld dropped; camera "
      "missing packets %lld, timeouts %lld, underruns %lld, reconnects %lld; laser "
      "switches %lld (%lld late)\n",
      static_cast<long long>(s.frames_captured), static_cast<double>(s.frames_captured) / 60.0,
      static_cast<long long>(s.frames_processed), static_cast<long long>(s.frames_dropped),
      static_cast<long long>(s.camera_missing_packets), static_cast<long long>(s.camera_timeouts),
      static_cast<long long>(s.camera_underruns), static_cast<long long>(s.camera_reconnects),
      static_cast<long long>(s.laser_switches), static_cast<long long>(s.laser_late_switches));
  EXPECT_GT(s.frames_captured, 60 * 20) << out;
  EXPECT_EQ(s.frames_captured, s.frames_processed + s.frames_dropped) << out;
  // Sanitized, the daemon runs several times slower: the ring may overflow, and on a loaded
  // machine a second without a frame (taken for a lost camera) has been seen once.
  if (!kSanitized) {
    EXPECT_EQ(s.frames_dropped, 0) << out;
    EXPECT_EQ(s.camera_reconnects, 0);
  }
  EXPECT_EQ(s.camera_missing_packets, 0);
}

TEST_F(AravisTest, DaemonReconnectsAfterTheCameraIsKilledAndLaserIsOffMeanwhile) {
  auto fake = std::make_unique<FakeCamera>();
  ASSERT_TRUE(fake->wait_ready());
  DaemonRun run = start_daemon("restart", fake_camera_at_1280(500), "on", 10);
  // Wait for frames (the laser goes on with the first one), then pull the plug.
  bool streaming = false;
  for (int i = 0; i < 200 && !streaming; ++i) {
    for (const auto& e : pin_events(run.pins))
      streaming |= e.event == "set" && e.level == 1;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(streaming) << read_text(run.output);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::int64_t killed = laserline::hal::monotonic_ns();
  fake->kill();
  std::this_thread::sleep_for(std::chrono::seconds(2));
  const std::int64_t restarted = laserline::hal::monotonic_ns();
  fake = std::make_unique<FakeCamera>();
  const int status = wait_exit(run.pid);
  const std::string out = read_text(run.output);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;

  // The pin: on before the kill, off from (shortly after) the kill until after the restart, on
  // again with the frames, off at the end.
  const auto events = pin_events(run.pins);
  std::int64_t off_at = 0;
  std::int64_t on_again = 0;
  for (const auto& e : events) {
    if (e.event != "set") continue;
    if (e.level == 0 && e.mono_ns > killed && off_at == 0) off_at = e.mono_ns;
    if (e.level == 1 && e.mono_ns > killed) {
      EXPECT_GT(e.mono_ns, restarted) << "laser on while the camera was gone";
      if (on_again == 0) on_again = e.mono_ns;
    }
  }
  ASSERT_NE(off_at, 0) << "the laser never went off after the camera was killed";
  ASSERT_NE(on_again, 0) << "frames never came back:\n" << out;
  std::printf(
      "camera killed: laser off after %.3f s; camera restarted: laser on again after "
      "%.3f s\n",
      static_cast<double>(off_at - killed) * 1e-9,
      static_cast<double>(on_again - restarted) * 1e-9);
  EXPECT_EQ(events.back().level, 0);
  const auto all = statuses(run.lcm_log);
  ASSERT_FALSE(all.empty());
  EXPECT_GE(all.back().camera_reconnects, 1);
}

// Simulated laser frames served over the real GigE path by our own fake camera, whose laser is
// the stand-in pin's real level at each exposure: the daemon's per-frame laser state is checked
// against the light in the image.
TEST_F(AravisTest, DaemonLaserStateMatchesTheLightInFramesOverGigE) {
  const auto pins = g_dir / "scanner.pins";  // the daemon's pin log (start_daemon's name)
  const pid_t scanner = spawn({FAKE_GIGE_SCANNER_PATH, "--serial", "LL01", "--width", "640",
                               "--height", "480", "--pins", pins.string()},
                              {}, g_dir / "scanner.out");
  bool ready = false;
  for (int i = 0; i < 100 && !ready; ++i) {
    ready = read_text(g_dir / "scanner.out").find("ready") != std::string::npos;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(ready) << read_text(g_dir / "scanner.out");
  std::filesystem::remove(pins);
  DaemonRun run = start_daemon(
      "scanner",
      "camera: {backend: aravis, device: LL01, frame_rate_hz: 50, packet_size: 1400}\n"
      "calibration: {camera: {width: 640, height: 480, fx: 704, fy: 704, cx: 319.5, cy: 239.5}}\n"
      "detector: {name: maxvalue, maxvalue: {threshold: 100}}\n",
      "alternate", 4);
  const int status = wait_exit(run.pid);
  kill(scanner, SIGTERM);
  wait_exit(scanner);
  const std::string out = read_text(run.output);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;

  int frames = 0, lit = 0, matches = 0, claimed_on = 0;
  lcm::LogFile log(run.lcm_log.string(), "r");
  ASSERT_TRUE(log.good());
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    if (event->channel != "LASERLINE_PROFILE") continue;
    laserline::profile_t p;
    ASSERT_GT(p.decode(event->data, 0, static_cast<int>(event->datalen)), 0);
    int valid = 0;
    for (const auto& point : p.points)
      valid += point.valid ? 1 : 0;
    const bool light = valid > 640 / 4;  // the line crosses most columns when the laser is on
    ++frames;
    lit += light;
    claimed_on += p.laser_on;
    matches += light == p.laser_on;
  }
  const auto all = statuses(run.lcm_log);
  ASSERT_FALSE(all.empty());
  std::printf(
      "simulated scanner over GigE, alternate at 50 Hz: %d frames, %d claimed on, %d lit; "
      "claimed state matches the light in %d (%.1f %%); %lld flagged late\n",
      frames, claimed_on, lit, matches, 100.0 * matches / std::max(frames, 1),
      static_cast<long long>(all.back().laser_late_switches));
  // Sanitized, the scanner renders (and the daemon runs) several times slower.
  EXPECT_GT(frames, kSanitized ? 20 : 50) << out;
  EXPECT_GT(lit, frames / 4) << "the laser line never showed";
  EXPECT_LT(lit, frames * 3 / 4) << "the laser line never went off";
  // Free-running, a frame exposed before its switch shows the old state (how many depends on the
  // machine's load; none on an idle one): most must match, not all.
  EXPECT_GT(matches, frames * (kSanitized ? 6 : 75) / (kSanitized ? 10 : 100));
}

// --check-config's look for the camera: the fake camera is found with its model, serial and
// formats, and nothing is configured; an address nothing answers at (127.0.0.2 in this private
// namespace) and a pixel format the camera lacks are one line each.
TEST_F(AravisTest, ProbeFindsTheCameraOrSaysWhyNot) {
  std::string found;
  std::string error;
  const auto started = std::chrono::steady_clock::now();
  AravisCameraOptions unanswered = options(640, 480, 30);
  unanswered.device = "127.0.0.2";
  AravisCamera nobody(unanswered);
  EXPECT_FALSE(nobody.probe(&found, &error));
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  EXPECT_EQ(error,
            "device '127.0.0.2': not among the 0 cameras that answered the discovery, and nothing "
            "answers at that address (Can't connect to device at address '127.0.0.2')");
  EXPECT_LT(took_s, 6.0);
  std::printf("no camera at 127.0.0.2: said so after %.1f s\n", took_s);
  std::fflush(stdout);  // before the fake camera forks

  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  AravisCamera camera(options(640, 480, 30));
  ASSERT_TRUE(camera.probe(&found, &error)) << error;
  EXPECT_EQ(found.rfind("device '127.0.0.1': Aravis Fake, serial GV01, id Aravis-Fake-GV01; "
                        "formats ",
                        0),
            0u)
      << found;
  EXPECT_NE(found.find("Mono8"), std::string::npos) << found;

  AravisCameraOptions mono12 = options(640, 480, 30);
  mono12.pixel_format = "Mono12";
  AravisCamera no_format(mono12);
  EXPECT_FALSE(no_format.probe(&found, &error));
  EXPECT_EQ(error.rfind("device '127.0.0.1': Aravis Fake, serial GV01, id Aravis-Fake-GV01: "
                        "pixel_format 'Mono12' is not among its formats (",
                        0),
            0u)
      << error;
}

// The same through laserlined --check-config --probe: one line for the camera, then the verdict;
// without --probe the file alone is checked, and an absent camera passes.
TEST_F(AravisTest, CheckConfigReportsTheCameraItFinds) {
  const std::filesystem::path config = g_dir / "check.yaml";
  auto check = [&](const std::string& device) {
    std::ofstream(config) << "camera: {backend: aravis, device: " << device
                          << ", width: 320, height: 240}\n"
                             "calibration: {camera: {width: 320, height: 240, fx: 350, fy: 350}}\n"
                             "detector: {name: maxvalue}\n";
    return laserline::test_support::run_command(
        std::string(LASERLINED_PATH) + " --check-config --probe --config " + config.string());
  };
  const auto nobody = check("127.0.0.2");
  EXPECT_EQ(nobody.exit_code, 1) << nobody.out;
  EXPECT_EQ(nobody.out,
            "laserlined: camera (aravis): device '127.0.0.2': not among the 0 cameras that "
            "answered the discovery, and nothing answers at that address (Can't connect to "
            "device at address '127.0.0.2')\n"
            "laserlined: " +
                config.string() + ": configuration is valid, its hardware is not all there\n");
  const auto file_alone = laserline::test_support::run_command(
      std::string(LASERLINED_PATH) + " --check-config --config " + config.string());
  EXPECT_EQ(file_alone.exit_code, 0) << file_alone.out;
  EXPECT_EQ(file_alone.out, "laserlined: " + config.string() + ": configuration is valid\n");
  FakeCamera fake;
  ASSERT_TRUE(fake.wait_ready());
  const auto found = check("127.0.0.1");
  EXPECT_EQ(found.exit_code, 0) << found.out;
  EXPECT_EQ(found.out.rfind("laserlined: camera (aravis): device '127.0.0.1': Aravis Fake, serial "
                            "GV01",
                            0),
            0u)
      << found.out;
  EXPECT_NE(found.out.find("\nlaserlined: " + config.string() +
                           ": configuration is valid, its hardware is there\n"),
            std::string::npos)
      << found.out;
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  g_namespace_problem = laserline::test::enter_private_network();
  g_dir = std::filesystem::temp_directory_path() / ("laserline_aravis_" + std::to_string(getpid()));
  std::filesystem::create_directories(g_dir);
  const int result = RUN_ALL_TESTS();
  std::filesystem::remove_all(g_dir);
  return result;
}
