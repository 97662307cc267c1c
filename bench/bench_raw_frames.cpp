// Does publishing raw frames delay profiles? Runs the whole frame path (simulated camera at
// 1280x1024, 30 Hz, maxvalue detector, LCM over UDP multicast on loopback in a private network
// namespace) with raw frames off and at 10 Hz full size with each compression, alternating the
// runs so that the machine's own noise spreads over all of them, and prints the profile latency
// (frame arrival -> profile published, the daemon's own share, and exposure -> published).
//
// Run (root, or a user allowed user namespaces):
//   build/default/bench/laserline_bench_raw_frames [seconds per run, default 10] [rounds, default
//   2]
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "daemon/backends.hpp"
#include "daemon/config.hpp"
#include "daemon/frame_path.hpp"
#include "private_network.hpp"

namespace {

using laserline::daemon::ImageCompression;

struct Variant {
  const char* name;
  bool raw;
  ImageCompression compression;
};

struct Result {
  double p50 = 0, p99 = 0, max = 0;  // arrival -> published, ms
  double exposure_p99 = 0;
  std::int64_t frames = 0, images = 0, dropped = 0, images_dropped = 0;
};

bool g_realtime = false;

// Throws std::runtime_error when the laser, the camera or the frame path does not start.
Result run(const Variant& v, double seconds) {
  laserline::daemon::DaemonConfig config = laserline::daemon::builtin_config();
  config.lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  config.frame_rate_hz = 30;
  config.image_every_n = v.raw ? 1 : 0;
  config.raw_frames.every_n = config.image_every_n;
  config.raw_frames.max_rate_hz = 10;
  config.raw_frames.compression = v.compression;
  config.raw_frames.downscale = 1;  // full 1280x1024 frames
  config.realtime = g_realtime;
  laserline::daemon::Backends backends = laserline::daemon::create_backends(config);
  std::string error;
  if (!backends.laser->open(&error) || !backends.camera->open(&error)) {
    throw std::runtime_error(error);
  }
  lcm::LCM lcm(config.lcm_url);
  laserline::daemon::FramePath path(config, *backends.camera, *backends.laser, *backends.detector,
                                    lcm);
  if (!path.start(&error)) {
    throw std::runtime_error(error);
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  path.stop();
  const auto s = path.summary();
  Result r;
  r.p50 = s.pipeline.p50_ms;
  r.p99 = s.pipeline.p99_ms;
  r.max = s.pipeline.max_ms;
  r.exposure_p99 = s.latency.p99_ms;
  r.frames = s.frames_processed;
  r.images = s.images_published;
  r.dropped = s.frames_dropped;
  r.images_dropped = path.counters().images_dropped.load();
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string problem = laserline::test::enter_private_network();
  if (!problem.empty()) {
    std::fprintf(stderr, "bench: no private network namespace: %s\n", problem.c_str());
    return 1;
  }
  const double seconds = argc > 1 ? std::atof(argv[1]) : 10.0;
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 2;
  g_realtime = argc > 3 && std::string(argv[3]) == "rt";
  const std::vector<Variant> variants = {{"raw frames off", false, ImageCompression::kNone},
                                         {"raw 10 Hz, none", true, ImageCompression::kNone},
                                         {"raw 10 Hz, zlib", true, ImageCompression::kZlib},
                                         {"raw 10 Hz, png", true, ImageCompression::kPng}};
  std::vector<std::vector<Result>> results(variants.size());
  for (int round = 0; round < rounds; ++round) {
    for (std::size_t i = 0; i < variants.size(); ++i) {
      try {
        results[i].push_back(run(variants[i], seconds));
      } catch (const std::runtime_error& e) {
        std::fprintf(stderr, "bench: %s\n", e.what());
        return 1;
      }
      const Result& r = results[i].back();
      std::fprintf(stderr, "round %d %-16s p99 %.2f ms (%lld frames, %lld raw)\n", round,
                   variants[i].name, r.p99, static_cast<long long>(r.frames),
                   static_cast<long long>(r.images));
    }
  }
  std::printf(
      "1280x1024 sim camera at 30 Hz, maxvalue, %d x %.0f s per variant, %s; profile latency "
      "arrival->published (ms), worst round's p99 and the mean of the rounds' p99\n",
      rounds, seconds, g_realtime ? "camera/worker SCHED_FIFO" : "normal scheduling");
  std::printf("%-16s %8s %9s %9s %8s %13s %8s %8s %10s\n", "variant", "p50", "p99 mean",
              "p99 worst", "max", "exp->pub p99", "frames", "raw", "raw drops");
  double off_mean = 0;
  for (std::size_t i = 0; i < variants.size(); ++i) {
    double p50 = 0, p99 = 0, worst = 0, max = 0, exposure = 0;
    std::int64_t frames = 0, images = 0, images_dropped = 0;
    for (const Result& r : results[i]) {
      p50 += r.p50 / rounds;
      p99 += r.p99 / rounds;
      worst = std::max(worst, r.p99);
      max = std::max(max, r.max);
      exposure += r.exposure_p99 / rounds;
      frames += r.frames;
      images += r.images;
      images_dropped += r.images_dropped;
    }
    if (i == 0) off_mean = p99;
    std::printf("%-16s %8.2f %9.2f %9.2f %8.2f %13.2f %8lld %8lld %10lld  p99 %+.0f%%\n",
                variants[i].name, p50, p99, worst, max, exposure, static_cast<long long>(frames),
                static_cast<long long>(images), static_cast<long long>(images_dropped),
                off_mean > 0 ? 100.0 * (p99 - off_mean) / off_mean : 0.0);
  }
  return 0;
}
