#pragma once

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "pipeline/parts.hpp"

namespace laserline::daemon {

// The threads that share one frame's detection (pipeline.worker_threads): the worker runs part 0
// of each stage itself, and parts - 1 helper threads, made in start(), run the others. A stage is
// handed over without a lock or an allocation: the worker publishes the work and bumps a
// generation counter, the helpers (spinning a little, then asleep on the counter: a futex, woken
// only when one sleeps) take
// part 1, 2, ... and count down; the worker waits for the count to reach zero the same way.
// Thread context: construct, start(), stop() from the owning thread; run() from one thread at a
// time (the worker), between start() and stop(). Without helpers (one part, or not started)
// run() does every part on the calling thread.
class WorkerPool final : public pipeline::PartRunner {
 public:
  explicit WorkerPool(int parts);
  ~WorkerPool() override;
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int parts() const override { return parts_; }
  void run(pipeline::PartWork work) override;
  // Makes the helper threads (allocates). `cpus`: how many CPUs the threads may run on; with more
  // threads than that they never spin (a spinning helper would keep a CPU the others need: at
  // SCHED_FIFO until it sleeps), they sleep at once. 0: this process's CPUs.
  void start(int cpus = 0);
  // Ends and joins them; run() must not be under way.
  void stop();
  // The helper threads (parts() - 1 once started), for names and priorities.
  std::vector<std::thread>& helpers() { return helpers_; }

 private:
  // Runs `part` of every stage after generation `seen`.
  void helper_loop(int part, std::uint32_t seen);

  const int parts_;
  bool spin_ = true;  // wait by spinning first (enough CPUs for every thread)
  std::vector<std::thread> helpers_;
  // The stage under way (valid while its generation is the current one).
  const pipeline::PartWork* work_ = nullptr;
  alignas(64) std::atomic<std::uint32_t> generation_{0};
  alignas(64) std::atomic<std::int32_t> remaining_{0};
  alignas(64) std::atomic<bool> stopping_{false};
  // Whether a wake-up syscall is needed: helpers asleep on generation_, the worker on remaining_.
  std::atomic<std::int32_t> sleepers_{0};
  std::atomic<bool> waiting_{false};
};

}  // namespace laserline::daemon
