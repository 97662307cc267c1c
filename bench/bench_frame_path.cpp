// Benchmarks of the frame path's hot parts, each beside a straightforward reference measured in
// the same run:
//   ring:     SpscRing vs a std::mutex + std::deque queue, one producer and one consumer thread
//   maxvalue: MaxValueDetector vs per-column cv::minMaxLoc with the same sub-pixel fit
//   sim:      SimScene::render (how fast the simulated camera can go)
// Run: build/default/bench/laserline_bench [--benchmark_filter=...] [--benchmark_format=json]
#include <benchmark/benchmark.h>

#include <hwy/targets.h>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <thread>

#include "bench_scenes.hpp"
#include "daemon/spsc_ring.hpp"
#include "hal/sim/sim_scene.hpp"
#include "pipeline/kernels/kernels.hpp"
#include "pipeline/maxvalue_detector.hpp"
#include "pipeline/subpixel.hpp"

namespace {

using laserline::daemon::SpscRing;

struct Item {
  std::uint64_t sequence;
  std::uint64_t payload[7];  // a cache line, like a small slot header
};
constexpr std::int64_t kItemsPerIteration = 1 << 16;

void BM_ring_spsc(benchmark::State& state) {
  SpscRing<Item> ring(1024, Item{});
  for (auto _ : state) {
    std::thread producer([&] {
      for (std::int64_t i = 0; i < kItemsPerIteration;) {
        Item* slot = ring.try_claim();
        if (slot == nullptr) continue;
        slot->sequence = static_cast<std::uint64_t>(i++);
        ring.publish();
      }
    });
    std::uint64_t sum = 0;
    for (std::int64_t received = 0; received < kItemsPerIteration;) {
      Item* slot = ring.front();
      if (slot == nullptr) continue;
      sum += slot->sequence;
      ring.pop();
      ++received;
    }
    producer.join();
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * kItemsPerIteration);
}
BENCHMARK(BM_ring_spsc)->UseRealTime()->Unit(benchmark::kMillisecond);

// Reference: the queue one writes first, a mutex around a deque (bounded the same way).
void BM_ring_reference_mutex_deque(benchmark::State& state) {
  std::mutex mutex;
  std::deque<Item> queue;
  for (auto _ : state) {
    std::thread producer([&] {
      for (std::int64_t i = 0; i < kItemsPerIteration;) {
        std::lock_guard<std::mutex> lock(mutex);
        if (queue.size() >= 1024) continue;
        queue.push_back(Item{static_cast<std::uint64_t>(i++), {}});
      }
    });
    std::uint64_t sum = 0;
    for (std::int64_t received = 0; received < kItemsPerIteration;) {
      std::lock_guard<std::mutex> lock(mutex);
      if (queue.empty()) continue;
      sum += queue.front().sequence;
      queue.pop_front();
      ++received;
    }
    producer.join();
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * kItemsPerIteration);
}
BENCHMARK(BM_ring_reference_mutex_deque)->UseRealTime()->Unit(benchmark::kMillisecond);

std::vector<std::uint8_t> sim_frame(int width, int height) {
  laserline::hal::SimScene scene(sim_options(width, height));
  std::vector<std::uint8_t> pixels(scene.format().bytes());
  scene.render(10, true, pixels);
  return pixels;
}

void BM_maxvalue_detector(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  const std::vector<std::uint8_t> pixels = sim_frame(width, height);
  laserline::pipeline::MaxValueDetector detector(40);
  detector.reset(width, height);
  laserline::pipeline::Profile profile(detector.max_points(width, height));
  const laserline::pipeline::ImageView view{pixels.data(), width, height, width};
  for (auto _ : state) {
    detector.detect(view, {}, profile);
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_maxvalue_detector)
    ->Args({1280, 1024})
    ->Args({2048, 1536})
    ->Unit(benchmark::kMillisecond);

// Reference: what one writes with OpenCV first, a minMaxLoc per column, the same fit.
void BM_maxvalue_reference_opencv(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  std::vector<std::uint8_t> pixels = sim_frame(width, height);
  const cv::Mat image(height, width, CV_8UC1, pixels.data());
  laserline::pipeline::Profile profile(static_cast<std::size_t>(width));
  for (auto _ : state) {
    profile.clear();
    for (int u = 0; u < width; ++u) {
      double max_value = 0;
      cv::Point at;
      cv::minMaxLoc(image.col(u), nullptr, &max_value, nullptr, &at);
      if (max_value < 40) continue;
      const int v = at.y;
      float offset = 0;
      if (v > 0 && v + 1 < height) {
        offset = laserline::pipeline::gaussian_offset(image.at<std::uint8_t>(v - 1, u),
                                                      static_cast<float>(max_value),
                                                      image.at<std::uint8_t>(v + 1, u));
      }
      const double mean = std::max(cv::mean(image.col(u))[0], 1.0);
      laserline::pipeline::ProfilePoint p;
      p.u = u;
      p.v = static_cast<float>(v) + offset;
      p.snr_db = static_cast<float>(20.0 * std::log10(max_value / mean));
      profile.add(p);
    }
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_maxvalue_reference_opencv)
    ->Args({1280, 1024})
    ->Args({2048, 1536})
    ->Unit(benchmark::kMillisecond);

void BM_sim_render(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  laserline::hal::SimScene scene(sim_options(width, height));
  std::vector<std::uint8_t> pixels(scene.format().bytes());
  std::uint64_t sequence = 0;
  for (auto _ : state) {
    scene.render(sequence++, true, pixels);
    benchmark::DoNotOptimize(pixels.data());
  }
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_sim_render)->Args({1280, 1024})->Args({2048, 1536})->Unit(benchmark::kMillisecond);

}  // namespace

// --kernel_target=NAME (e.g. AVX2, SSE4, SCALAR): the vector kernels of pipeline/kernels/ run on
// that target instead of the best the CPU has, to compare them in the same conditions. The
// target is in the output's context ("kernels").
int main(int argc, char** argv) {
  const std::string flag = "--kernel_target=";
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string argument = argv[i];
    if (argument.rfind(flag, 0) != 0) {
      argv[kept++] = argv[i];
      continue;
    }
    const std::string wanted = argument.substr(flag.size());
    std::int64_t chosen = 0;
    std::string known;
    for (const std::int64_t target : hwy::SupportedAndGeneratedTargets()) {
      if (wanted == hwy::TargetName(target)) chosen = target;
      known += std::string(" ") + hwy::TargetName(target);
    }
    if (chosen == 0) {
      std::fprintf(stderr, "laserline_bench: --kernel_target=%s: not one of%s\n", wanted.c_str(),
                   known.c_str());
      return 2;
    }
    hwy::SetSupportedTargetsForTest(chosen);
  }
  argc = kept;
  benchmark::AddCustomContext("kernels", laserline::pipeline::kernels::target_name());
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
