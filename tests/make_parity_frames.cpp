// Renders the standard simulated scenarios (tools/evaluation.hpp: mono and colour cameras, the
// laser below, beside and turned) into a frames file for profile_parity, as the detectors see
// them (a colour scene delivered as the laser's channel).
//   make_parity_frames OUT [WIDTH HEIGHT FRAMES]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "hal/pixel_conversion.hpp"
#include "hal/sim/sim_scene.hpp"
#include "parity_frames.hpp"
#include "tools/evaluation.hpp"

namespace {

using namespace laserline;

parity::ParityScenario render(const tools::Scenario& scenario, int frames) {
  parity::ParityScenario out;
  out.name = scenario.name;
  out.geometry = daemon::scanner_geometry(scenario.scene.calibration);
  hal::SimScene scene(scenario.scene);
  const hal::FrameFormat format = scene.format();
  const bool colour = scenario.scene.colour != hal::SimColour::kMono;
  std::vector<std::uint8_t> raw(colour ? scene.raw_bytes() : 0);
  const hal::PixelConverter converter =
      colour
          ? hal::PixelConverter(scene.raw_format(), format.width, format.height, scenario.channel)
          : hal::PixelConverter();
  for (int i = 0; i < frames; ++i) {
    parity::ParityFrame& f = out.frames.emplace_back();
    f.sequence = static_cast<std::uint64_t>(scenario.first_frame + i);
    f.laser_on = !scenario.alternate || f.sequence % 2 == 0;
    // Rows of exactly `width` bytes, as the file stores them.
    std::vector<std::uint8_t> pixels(format.bytes());
    if (colour) {
      scene.render(f.sequence, f.laser_on, raw);
      converter.convert(raw.data(), raw.size() / static_cast<std::size_t>(format.height),
                        pixels.data(), static_cast<std::size_t>(format.stride));
    } else {
      scene.render(f.sequence, f.laser_on, pixels);
    }
    f.pixels.resize(static_cast<std::size_t>(format.width) * format.height);
    for (int v = 0; v < format.height; ++v)
      std::copy_n(pixels.begin() + static_cast<std::ptrdiff_t>(v) * format.stride, format.width,
                  f.pixels.begin() + static_cast<std::ptrdiff_t>(v) * format.width);
  }
  return out;
}

// 0 (after one line on stderr) when `text` is not a whole number from 1 to 8192.
int positive(const char* text, const char* what) {
  char* end = nullptr;
  const long value = std::strtol(text, &end, 10);
  if (end == text || *end != 0 || value <= 0 || value > 8192) {
    std::fprintf(stderr, "make_parity_frames: %s '%s' is not a whole number from 1 to 8192\n", what,
                 text);
    return 0;
  }
  return static_cast<int>(value);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 && argc != 5) {
    std::fprintf(stderr, "usage: make_parity_frames OUT [WIDTH HEIGHT FRAMES]\n");
    return 2;
  }
  const int width = argc == 5 ? positive(argv[2], "WIDTH") : 640;
  const int height = argc == 5 ? positive(argv[3], "HEIGHT") : 512;
  const int frames = argc == 5 ? positive(argv[4], "FRAMES") : 6;
  if (width == 0 || height == 0 || frames == 0) return 2;
  try {
    parity::FramesWriter writer(argv[1]);
    int scenarios = 0;
    for (const tools::Scenario& scenario : tools::standard_scenarios(width, height)) {
      writer.add(render(scenario, frames));
      ++scenarios;
    }
    writer.close();
    std::printf("make_parity_frames: %d scenarios of %d frames of %dx%d in %s\n", scenarios, frames,
                width, height, argv[1]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "make_parity_frames: %s\n", e.what());
    return 1;
  }
  return 0;
}
