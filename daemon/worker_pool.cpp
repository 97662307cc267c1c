#include "daemon/worker_pool.hpp"

#include <linux/futex.h>
#include <sched.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <climits>

#include "hal/clock.hpp"

namespace laserline::daemon {

namespace {

// Spins before sleeping: between the stages of a frame the worker does the serial parts (the line
// selection, the homography's RANSAC: 0.4 ms in all at 2048x1536), and a helper woken from a futex
// arrives tens of microseconds late (measured: 2 threads at 0.61 of one thread's latency spinning
// ~0.2 ms, 0.57 spinning longer); a longer wait is between frames. The clock is read every
// kSpinsPerLook spins (vDSO: no system call).
constexpr std::int64_t kSpinNs = 500'000;
constexpr int kSpinsPerLook = 64;

inline void pause() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

// Sleeps while *word holds `value` (FUTEX_WAIT: returns at once if it no longer does), and wakes
// every sleeper on it. The callers count who sleeps, so that a stage whose helpers are still
// spinning makes no system call.
template <class T>
void sleep_while(const std::atomic<T>& word, T value) {
  static_assert(sizeof(T) == 4 && std::atomic<T>::is_always_lock_free);
  syscall(SYS_futex, reinterpret_cast<const T*>(&word), FUTEX_WAIT_PRIVATE, value, nullptr, nullptr,
          0);
}

template <class T>
void wake_all(std::atomic<T>& word) {
  syscall(SYS_futex, reinterpret_cast<T*>(&word), FUTEX_WAKE_PRIVATE, INT_MAX, nullptr, nullptr, 0);
}

}  // namespace

WorkerPool::WorkerPool(int parts) : parts_(std::clamp(parts, 1, pipeline::kMaxParts)) {}

WorkerPool::~WorkerPool() {
  stop();
}

void WorkerPool::start(int cpus) {
  if (!helpers_.empty()) return;
  if (cpus <= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    cpus = sched_getaffinity(0, sizeof set, &set) == 0 ? CPU_COUNT(&set) : 1;
  }
  spin_ = parts_ <= cpus;
  stopping_.store(false, std::memory_order_relaxed);
  helpers_.reserve(static_cast<std::size_t>(parts_ - 1));
  // The stage they wait for is the next one from now (a helper that starts late must not take a
  // stage run before it started as the one it has seen).
  const std::uint32_t seen = generation_.load(std::memory_order_relaxed);
  for (int part = 1; part < parts_; ++part)
    helpers_.emplace_back([this, part, seen] { helper_loop(part, seen); });
}

void WorkerPool::stop() {
  if (helpers_.empty()) return;
  stopping_.store(true, std::memory_order_relaxed);
  generation_.fetch_add(1, std::memory_order_release);
  wake_all(generation_);
  for (std::thread& helper : helpers_)
    helper.join();
  helpers_.clear();
}

void WorkerPool::run(pipeline::PartWork work) {
  if (helpers_.empty()) {
    for (int part = 0; part < parts_; ++part)
      work(part);
    return;
  }
  work_ = &work;
  remaining_.store(parts_ - 1, std::memory_order_relaxed);
  generation_.fetch_add(1, std::memory_order_seq_cst);  // publishes work_ and remaining_
  if (sleepers_.load(std::memory_order_seq_cst) > 0) wake_all(generation_);
  work(0);
  const std::int64_t spin_until = spin_ ? hal::monotonic_ns() + kSpinNs : 0;
  for (int spin = 1;; ++spin) {
    const std::int32_t left = remaining_.load(std::memory_order_acquire);
    if (left == 0) break;
    if (spin_ && (spin % kSpinsPerLook != 0 || hal::monotonic_ns() < spin_until)) {
      pause();
    } else {
      waiting_.store(true, std::memory_order_seq_cst);
      if (remaining_.load(std::memory_order_seq_cst) == left) sleep_while(remaining_, left);
      waiting_.store(false, std::memory_order_relaxed);
    }
  }
}

void WorkerPool::helper_loop(int part, std::uint32_t seen) {
  while (true) {
    std::uint32_t now = seen;
    const std::int64_t spin_until = spin_ ? hal::monotonic_ns() + kSpinNs : 0;
    for (int spin = 1; now == seen; ++spin) {
      if (spin_ && (spin % kSpinsPerLook != 0 || hal::monotonic_ns() < spin_until)) {
        pause();
      } else {
        sleepers_.fetch_add(1, std::memory_order_seq_cst);
        if (generation_.load(std::memory_order_seq_cst) == seen) sleep_while(generation_, seen);
        sleepers_.fetch_sub(1, std::memory_order_relaxed);
      }
      now = generation_.load(std::memory_order_acquire);
    }
    seen = now;
    if (stopping_.load(std::memory_order_relaxed)) return;
    (*work_)(part);
    if (remaining_.fetch_sub(1, std::memory_order_seq_cst) == 1 &&
        waiting_.load(std::memory_order_seq_cst)) {
      wake_all(remaining_);
    }
  }
}

}  // namespace laserline::daemon
