// The threads sharing a frame's detection (daemon/worker_pool.hpp, pipeline.worker_threads): every
// part run once per stage, on its own thread, every detector's profiles those of one thread, a
// clean stop; and the daemon's frame path with worker_threads 2 on the simulator's frames (the
// memory camera, paced by the frame path so that no frame is lost): every frame processed, the
// profiles those of one thread to the bit, the laser off at the end.
#include "daemon/worker_pool.hpp"

#include <gtest/gtest.h>
#include <pthread.h>
#include <unistd.h>
#include <laserline/profile_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "daemon/backends.hpp"
#include "daemon/config.hpp"
#include "daemon/frame_path.hpp"
#include "hal/sim/sim_scene.hpp"
#include "hal/yaml_reader.hpp"
#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"
#include "pipeline/detector.hpp"
#include "tools/evaluation.hpp"

namespace laserline {
namespace {

TEST(WorkerPool, RunsEveryPartOnceEachOnItsOwnThreadAndStops) {
  for (int parts = 1; parts <= 4; ++parts) {
    daemon::WorkerPool pool(parts);
    pool.start();
    ASSERT_EQ(pool.helpers().size(), static_cast<std::size_t>(parts - 1));
    std::vector<int> runs(static_cast<std::size_t>(parts), 0);  // each part's own counter
    std::vector<pthread_t> threads(static_cast<std::size_t>(parts));
    const pthread_t caller = pthread_self();
    for (int stage = 0; stage < 300; ++stage) {
      auto work = [&](int part) {
        ++runs[static_cast<std::size_t>(part)];
        threads[static_cast<std::size_t>(part)] = pthread_self();
      };
      pool.run(pipeline::PartWork(work));
      // Between two stages nothing runs: what the parts wrote is all there.
      for (int part = 0; part < parts; ++part)
        ASSERT_EQ(runs[static_cast<std::size_t>(part)], stage + 1) << "part " << part;
    }
    EXPECT_TRUE(pthread_equal(threads[0], caller)) << "the caller runs part 0 itself";
    for (int part = 1; part < parts; ++part) {
      EXPECT_FALSE(pthread_equal(threads[static_cast<std::size_t>(part)], caller));
      for (int other = 1; other < part; ++other) {
        EXPECT_FALSE(pthread_equal(threads[static_cast<std::size_t>(part)],
                                   threads[static_cast<std::size_t>(other)]));
      }
    }
    pool.stop();
    EXPECT_TRUE(pool.helpers().empty());
    // Stopped (or never started): every part on the caller.
    int after = 0;
    auto count = [&](int) { ++after; };
    pool.run(pipeline::PartWork(count));
    EXPECT_EQ(after, parts);
  }
}

TEST(WorkerPool, StopsWhileItsHelpersSleep) {
  daemon::WorkerPool pool(3);
  pool.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // past their spinning: asleep
  pool.stop();
  EXPECT_TRUE(pool.helpers().empty());
}

TEST(WorkerPool, EveryDetectorGivesTheProfilesOfOneThread) {
  for (const tools::Scenario& s : tools::standard_scenarios(640, 480)) {
    if (s.name != "ambient") continue;
    hal::SimScene scene(s.scene);
    const hal::FrameFormat format = scene.format();
    std::vector<std::vector<std::uint8_t>> frames;
    for (int i = 0; i < 4; ++i) {
      frames.emplace_back(format.bytes());
      scene.render(static_cast<std::uint64_t>(s.first_frame + i), true, frames.back());
    }
    pipeline::DetectorOptions options;
    options.geometry = daemon::scanner_geometry(s.scene.calibration);
    // The whole frame, and a region across two of the front end's three strips (so that of three
    // parts one has none).
    for (const pipeline::DetectionRegion& region :
         {pipeline::DetectionRegion{}, pipeline::DetectionRegion{100, 80, 300, 320}}) {
      for (const std::string& name : pipeline::detector_names()) {
        auto detect_all = [&](pipeline::PartRunner& runner) {
          const auto detector = pipeline::make_detector(name, options);
          detector->use_parts(runner);
          detector->reset(format.width, format.height);
          detector->set_region(region);
          std::vector<pipeline::Profile> profiles;
          for (std::size_t i = 0; i < frames.size(); ++i) {
            profiles.emplace_back(detector->max_points(format.width, format.height));
            detector->detect({frames[i].data(), format.width, format.height, format.stride},
                             {i, true}, profiles.back());
          }
          return profiles;
        };
        pipeline::SequentialParts one;
        const std::vector<pipeline::Profile> reference = detect_all(one);
        for (int parts : {2, 3}) {
          daemon::WorkerPool pool(parts);
          pool.start();
          const std::vector<pipeline::Profile> split = detect_all(pool);
          pool.stop();
          for (std::size_t i = 0; i < reference.size(); ++i) {
            ASSERT_EQ(split[i].size(), reference[i].size())
                << name << " in " << region.text() << ", " << parts << " threads, frame " << i;
            ASSERT_GT(reference[i].size(), 0u) << name << " in " << region.text();
            for (std::size_t k = 0; k < reference[i].size(); ++k) {
              const pipeline::ProfilePoint& p = reference[i].points()[k];
              const pipeline::ProfilePoint& q = split[i].points()[k];
              ASSERT_TRUE(p.u == q.u && std::memcmp(&p.v, &q.v, sizeof p.v) == 0 &&
                          p.valid == q.valid)
                  << name << " in " << region.text() << ", " << parts << " threads, frame " << i
                  << " point " << k;
            }
          }
        }
      }
    }
  }
}

// The frame path on the memory camera (rendered frames delivered as fast as the worker takes
// them), its profiles written to an LCM log and read back.
struct PathRun {
  daemon::FramePathSummary summary;
  std::vector<profile_t> profiles;
  bool laser_off_after = false;
};

PathRun run_path(int worker_threads) {
  PathRun run;
  const std::filesystem::path log_path = std::filesystem::temp_directory_path() /
                                         ("laserline_worker_pool_" + std::to_string(getpid()) +
                                          "_" + std::to_string(worker_threads) + ".lcmlog");
  const std::string text = R"(
camera:
  backend: memory
  memory: {frames: 6, loops: 4, rate_hz: 0}
  sim: {tilt_y_deg: 8}
calibration:
  camera: {width: 640, height: 480, fx: 700, fy: 700}
laser: {mode: on}
detector: {name: background}
pipeline: {worker_threads: )" +
                           std::to_string(worker_threads) +
                           R"(}
lcm: {url: "file://)" + log_path.string() +
                           R"(?mode=w", image_every_n: 0}
)";
  daemon::DaemonConfig config =
      daemon::parse_config(hal::load_yaml_text(text, "test.yaml"), "test.yaml");
  EXPECT_EQ(config.worker_threads, worker_threads);
  daemon::Backends backends = daemon::create_backends(config);
  std::string error;
  EXPECT_TRUE(backends.laser->open(&error)) << error;
  EXPECT_TRUE(backends.camera->open(&error)) << error;
  EXPECT_TRUE(backends.camera->paced_by_consumer());
  {
    lcm::LCM lcm(config.lcm_url);
    EXPECT_TRUE(lcm.good());
    daemon::FramePath path(config, *backends.camera, *backends.laser, *backends.detector, lcm);
    EXPECT_TRUE(path.start(&error)) << error;
    while (!path.source_ended())
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    path.stop();
    run.summary = path.summary();
    run.laser_off_after = !backends.laser->is_on();
  }
  messages::LcmLogReader reader;
  EXPECT_TRUE(reader.open(log_path.string(), &error)) << error;
  messages::LcmLogReader::Event event;
  messages::LcmLogReader::Damage damage;
  messages::Limits limits;
  while (reader.next(&event, &damage)) {
    if (event.channel != config.profile_channel) continue;
    run.profiles.emplace_back();
    EXPECT_TRUE(messages::decode(event.data.data(), event.data.size(), &run.profiles.back(), limits,
                                 &error))
        << error;
  }
  std::filesystem::remove(log_path);
  return run;
}

TEST(WorkerPoolFramePath, TwoThreadsProcessEveryFrameAsOneThreadDoes) {
  const PathRun one = run_path(1);
  const PathRun two = run_path(2);
  for (const PathRun* run : {&one, &two}) {
    EXPECT_EQ(run->summary.frames_captured, 24) << "four loops of six frames";
    EXPECT_EQ(run->summary.frames_processed, 24);
    EXPECT_EQ(run->summary.frames_dropped, 0);
    EXPECT_TRUE(run->laser_off_after);
  }
  ASSERT_EQ(one.profiles.size(), 24u);
  ASSERT_EQ(two.profiles.size(), one.profiles.size());
  std::size_t valid = 0;
  for (std::size_t i = 0; i < one.profiles.size(); ++i) {
    const profile_t& a = one.profiles[i];
    const profile_t& b = two.profiles[i];
    EXPECT_EQ(a.sequence, b.sequence);
    EXPECT_EQ(a.background_sequence, b.background_sequence) << "frame " << a.sequence;
    ASSERT_EQ(a.num_points, b.num_points) << "frame " << a.sequence;
    for (int k = 0; k < a.num_points; ++k) {
      const point_t& p = a.points[static_cast<std::size_t>(k)];
      const point_t& q = b.points[static_cast<std::size_t>(k)];
      valid += p.valid ? 1 : 0;
      ASSERT_TRUE(p.u == q.u && std::memcmp(&p.v, &q.v, sizeof p.v) == 0 &&
                  std::memcmp(&p.snr_db, &q.snr_db, sizeof p.snr_db) == 0 && p.valid == q.valid &&
                  std::memcmp(p.xyz, q.xyz, sizeof p.xyz) == 0)
          << "frame " << a.sequence << " point " << k;
    }
  }
  EXPECT_GT(valid, 24u * 300u) << "a line in every frame";
}

TEST(WorkerPoolConfig, RefusesWorkerThreadsOutsideWhatThePipelineSplits) {
  for (const char* bad : {"0", "9", "two"}) {
    const std::string text = std::string("pipeline: {worker_threads: ") + bad + "}\n";
    try {
      daemon::parse_config(hal::load_yaml_text(text, "bad.yaml"), "bad.yaml");
      ADD_FAILURE() << "worker_threads " << bad << " accepted";
    } catch (const std::exception& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find("bad.yaml"), std::string::npos) << message;
      EXPECT_NE(message.find("worker_threads"), std::string::npos) << message;
    }
  }
}

}  // namespace
}  // namespace laserline
