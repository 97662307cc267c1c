// Cost as the frame grows: every detector as the daemon makes it (pipeline::make_detector) at
// 640x480, 1280x1024, 2048x1536 and 4096x3000, one thread, on the scenes bench_frontend.cpp times
// them on at 2048x1536 (the `ambient` scan without sway for maxvalue, fir and background; the
// `pier` for backprojection), rendered at each size with the focal length scaled to the width.
// Each is fed eight consecutive frames of its scan in turn (the sequence restarts every eight).
//   scaling/<detector>/<width>x<height>   counters: pixels, points (per frame), normalised_rows
// Run, and plot (docs/figures/scaling.png):
//   build/default/bench/laserline_bench --benchmark_filter='^scaling/'
//       --benchmark_out=scaling.json --benchmark_out_format=json   (one line)
//   scripts/plot-scaling.py scaling.json
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "hal/sim/sim_scene.hpp"
#include "pipeline/detector.hpp"
#include "pipeline/frontend.hpp"
#include "tools/evaluation.hpp"

namespace {

using namespace laserline;

struct Size {
  int width, height;
};
constexpr Size kSizes[] = {{640, 480}, {1280, 1024}, {2048, 1536}, {4096, 3000}};
constexpr const char* kDetectors[] = {"maxvalue", "fir", "background", "backprojection"};
constexpr int kFrames = 8;

hal::SimSceneOptions scene_for(const std::string& detector, Size size) {
  const char* name = detector == "backprojection" ? "pier" : "ambient";
  for (const tools::Scenario& s : tools::standard_scenarios(size.width, size.height)) {
    if (s.name != name) continue;
    hal::SimSceneOptions scene = s.scene;
    if (detector != "backprojection") {
      scene.sway_m = 0;
      scene.sway_deg = 0;
    }
    return scene;
  }
  std::abort();
}

// The frames of one scene at one size; only the last asked for is kept (4096x3000 takes 100 MB).
const std::vector<std::vector<std::uint8_t>>& frames_for(const hal::SimSceneOptions& scene,
                                                         const std::string& key) {
  static std::string cached_key;
  static std::vector<std::vector<std::uint8_t>> cached;
  if (key != cached_key) {
    cached.clear();
    cached_key = key;
    hal::SimScene sim(scene);
    for (int k = 0; k < kFrames; ++k) {
      cached.emplace_back(sim.format().bytes());
      sim.render(10 + static_cast<std::uint64_t>(k), true, cached.back());
    }
  }
  return cached;
}

void BM_scaling(benchmark::State& state, const std::string& name, Size size) {
  const hal::SimSceneOptions scene = scene_for(name, size);
  const auto& frames =
      frames_for(scene, std::string(name == "backprojection" ? "pier" : "ambient") +
                            std::to_string(size.width));
  pipeline::DetectorOptions options;
  options.geometry = daemon::scanner_geometry(scene.calibration);
  const std::unique_ptr<pipeline::Detector> detector = pipeline::make_detector(name, options);
  detector->reset(size.width, size.height);
  pipeline::Profile profile(detector->max_points(size.width, size.height));
  std::uint64_t sequence = 0;
  std::size_t points = 0;
  for (auto _ : state) {
    const pipeline::ImageView view{frames[sequence % kFrames].data(), size.width, size.height,
                                   size.width};
    detector->detect(view, {sequence, true}, profile);
    points += profile.size();
    ++sequence;
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["pixels"] = static_cast<double>(size.width) * size.height;
  state.counters["points"] = static_cast<double>(points) / static_cast<double>(sequence);
  if (name != "maxvalue") {
    // The rows the front-end works on: set by the depth range and the laser's width in pixels,
    // both of which grow with the focal length, so they stay nearly the same at every size.
    pipeline::Frontend frontend(options.geometry, options.frontend);
    frontend.reset(size.width, size.height);
    state.counters["normalised_rows"] = frontend.rows().rows();
  }
}

const bool registered = [] {
  for (const char* detector : kDetectors) {
    for (const Size size : kSizes) {
      const std::string name = std::string("scaling/") + detector + "/" +
                               std::to_string(size.width) + "x" + std::to_string(size.height);
      benchmark::RegisterBenchmark(name.c_str(), BM_scaling, std::string(detector), size)
          ->Unit(benchmark::kMillisecond);
    }
  }
  return true;
}();

}  // namespace
