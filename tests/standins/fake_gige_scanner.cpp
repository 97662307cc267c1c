// A test-only GigE Vision camera that sees the simulated scanner: Aravis's fake GigE camera
// (arv_gv_fake_camera_new) with its fill pattern replaced by SimScene frames, so laserlined's
// aravis backend receives simulated laser frames over the real GVCP/GVSP network path.
//
//   fake_gige_scanner --serial LL01 --width 640 --height 480 [--pins FILE]
//                     [--lost-per-thousand N]
//
// The laser in each frame is the level the stand-in GPIO chip (tests/standins/gpiochip_shim.cpp)
// logged last for line 0 in FILE when the frame is filled (its exposure): the image shows what the
// pin really did, not what the daemon meant, so a test can check the daemon's per-frame laser state
// against the light. Without --pins the laser is always on. --lost-per-thousand: stream packets
// the camera leaves out, as arv-fake-gv-camera's -r. Runs until SIGTERM/SIGINT.
#include <arv.h>
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <string>
#include <vector>

#include "hal/sim/sim_scene.hpp"

namespace {

std::atomic<bool> g_running{true};

struct Scanner {
  laserline::hal::SimScene* scene = nullptr;
  ArvFakeCamera* camera = nullptr;
  int width = 0;
  int height = 0;
  std::string pins;
  std::streamoff pins_read = 0;  // how far the pin log was read
  bool laser_on = false;
  std::vector<std::uint8_t> frame;
};

// The level of line 0 now: the last level logged for it (the log only grows).
bool laser_level(Scanner& s) {
  if (s.pins.empty()) return true;
  std::ifstream in(s.pins);
  in.seekg(s.pins_read);
  std::string line;
  while (std::getline(in, line)) {
    if (in.eof()) break;  // a line still being written: read it next time
    s.pins_read += static_cast<std::streamoff>(line.size() + 1);
    long long mono = 0, wall = 0;
    unsigned offset = 0;
    int level = 0;
    if (std::sscanf(line.c_str(), "%lld %lld %u %d", &mono, &wall, &offset, &level) == 4 &&
        offset == 0) {
      s.laser_on = level != 0;
    }
  }
  return s.laser_on;
}

// Aravis's fill-pattern hook, on the fake camera's streaming thread, once per frame.
void fill(ArvBuffer* buffer, void* data, guint32 /*exposure_us*/, guint32 /*gain*/,
          ArvPixelFormat pixel_format) {
  auto& s = *static_cast<Scanner*>(data);
  // The buffer's received size is only set after this hook; its memory holds the payload.
  std::size_t ignored = 0;
  auto* out = static_cast<std::uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, &ignored)));
  const std::size_t payload = arv_fake_camera_get_payload(s.camera);
  const bool matches = pixel_format == ARV_PIXEL_FORMAT_MONO_8 &&
                       arv_buffer_get_image_width(buffer) == s.width &&
                       arv_buffer_get_image_height(buffer) == s.height && payload >= s.frame.size();
  if (!matches) {
    std::memset(out, 0, payload);
    return;
  }
  s.scene->render(arv_buffer_get_frame_id(buffer), laser_level(s), s.frame);
  std::memcpy(out, s.frame.data(), s.frame.size());
}

void on_signal(int) {
  g_running.store(false);
}

}  // namespace

int main(int argc, char** argv) {
  std::string serial = "LL01";
  Scanner scanner;
  double lost_per_thousand = 0;
  scanner.width = 640;
  scanner.height = 480;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    if (key == "--serial") {
      serial = argv[i + 1];
    } else if (key == "--width") {
      scanner.width = std::atoi(argv[i + 1]);
    } else if (key == "--height") {
      scanner.height = std::atoi(argv[i + 1]);
    } else if (key == "--pins") {
      scanner.pins = argv[i + 1];
    } else if (key == "--lost-per-thousand") {
      lost_per_thousand = std::atof(argv[i + 1]);
    } else {
      std::fprintf(stderr, "fake_gige_scanner: unknown argument '%s'\n", key.c_str());
      return 2;
    }
  }
  laserline::hal::SimSceneOptions options;
  options.calibration.camera.width = scanner.width;
  options.calibration.camera.height = scanner.height;
  options.calibration.camera.fx = options.calibration.camera.fy = scanner.width * 1.1;
  options.calibration.camera.cx = (scanner.width - 1) / 2.0;
  options.calibration.camera.cy = (scanner.height - 1) / 2.0;
  options.tilt_y_deg = 8;
  laserline::hal::SimScene scene(options);
  scanner.scene = &scene;
  scanner.frame.assign(scene.format().bytes(), 0);

  ArvGvFakeCamera* camera = arv_gv_fake_camera_new("127.0.0.1", serial.c_str());
  if (camera == nullptr || !arv_gv_fake_camera_is_running(camera)) {
    std::fprintf(stderr, "fake_gige_scanner: cannot serve on 127.0.0.1\n");
    return 1;
  }
  if (lost_per_thousand > 0) {
    g_object_set(camera, "gvsp-lost-ratio", lost_per_thousand / 1000.0, nullptr);
  }
  scanner.camera = arv_gv_fake_camera_get_fake_camera(camera);
  arv_fake_camera_set_fill_pattern(scanner.camera, fill, &scanner);
  signal(SIGTERM, on_signal);
  signal(SIGINT, on_signal);
  std::printf("fake_gige_scanner: %s on 127.0.0.1 ready\n", serial.c_str());
  std::fflush(stdout);
  while (g_running.load())
    g_usleep(50'000);
  g_object_unref(camera);
  return 0;
}
