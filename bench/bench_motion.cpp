// Frame-to-frame homography estimation (pipeline/motion.hpp) on simulated 2048x1536 mono8 frames
// of a swaying camera: each update() builds the pyramid, tracks the previous frame's features,
// runs RANSAC and the refit, and finds the features for the next frame.
// Run: build/default/bench/laserline_bench --benchmark_filter=homography
#include <benchmark/benchmark.h>

#include <cstdint>
#include <vector>

#include "hal/sim/sim_scene.hpp"
#include "pipeline/motion.hpp"

namespace {

void BM_frontend_homography_estimation(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  laserline::hal::SimSceneOptions o;
  o.calibration.camera.width = width;
  o.calibration.camera.height = height;
  o.calibration.camera.fx = o.calibration.camera.fy = 1400.0 * width / 1280.0;
  o.calibration.camera.cx = (width - 1) / 2.0;
  o.calibration.camera.cy = (height - 1) / 2.0;
  o.tilt_y_deg = 8;
  laserline::hal::SimScene scene(o);
  // Frames a few apart, so that the camera has visibly moved; the laser is on (the filter works).
  std::vector<std::vector<std::uint8_t>> frames(2,
                                                std::vector<std::uint8_t>(scene.format().bytes()));
  scene.render(10, true, frames[0]);
  scene.render(13, true, frames[1]);

  laserline::pipeline::MotionEstimator estimator;
  estimator.reset(width, height);
  std::size_t next = 0;
  const auto feed = [&] {
    const laserline::pipeline::ImageView view{frames[next].data(), width, height, width};
    next = 1 - next;
    return estimator.update(view);
  };
  feed();
  laserline::pipeline::MotionEstimate estimate;
  std::int64_t valid = 0;
  for (auto _ : state) {
    estimate = feed();
    valid += estimate.valid ? 1 : 0;
    benchmark::DoNotOptimize(estimate);
  }
  state.counters["valid"] = static_cast<double>(valid) / static_cast<double>(state.iterations());
  state.counters["inliers"] = estimate.inliers;
  state.counters["tracked"] = estimate.tracked;
  state.counters["rejected_on_laser"] = estimate.rejected_on_laser;
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_frontend_homography_estimation)->Args({2048, 1536})->Unit(benchmark::kMillisecond);

}  // namespace
