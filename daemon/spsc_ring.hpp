#pragma once

#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <new>
#include <stdexcept>
#include <vector>

namespace laserline::daemon {

// Single-producer single-consumer ring of preallocated slots, written and read in place
// (rigtorp's SPSCQueue habit: power-of-two capacity, indices on their own cache lines, each side
// caching the other's index, acquire/release at every access).
//
// The producer never blocks: try_claim() returns nullptr when the ring is full and the caller
// drops and counts. The consumer may sleep in wait() on a futex; the producer only makes the
// wake-up syscall when the consumer is actually asleep, so a busy ring costs no syscalls.
//
// Thread context: exactly one producer thread calls try_claim()/publish(); exactly one consumer
// thread calls front()/pop()/wait(); wake() may be called from any thread (e.g. to stop).
template <typename T>
class SpscRing {
 public:
  // Every slot starts as a copy of `prototype`: allocate buffers here, never on the frame path.
  SpscRing(std::size_t capacity, const T& prototype) : slots_(capacity, prototype) {
    if (capacity < 2 || (capacity & (capacity - 1)) != 0) {
      throw std::invalid_argument("SpscRing capacity must be a power of two >= 2");
    }
    mask_ = capacity - 1;
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  std::size_t capacity() const { return slots_.size(); }

  // Producer: the next free slot to fill, or nullptr when full. The slot holds whatever an
  // earlier use left in it; publish() makes it visible to the consumer.
  T* try_claim() {
    const std::uint64_t write = write_.load(std::memory_order_relaxed);
    if (write - read_cache_ == slots_.size()) {
      read_cache_ = read_.load(std::memory_order_acquire);
      if (write - read_cache_ == slots_.size()) return nullptr;
    }
    return &slots_[write & mask_];
  }

  // Producer: hands the slot returned by try_claim() to the consumer.
  void publish() {
    write_.store(write_.load(std::memory_order_relaxed) + 1, std::memory_order_seq_cst);
    // seq_cst store above and load below pair with wait(): either the consumer sees the new
    // index or we see it waiting (no lost wake-up).
    if (sleeping_.load(std::memory_order_seq_cst)) wake();
  }

  // Consumer: the oldest published slot, or nullptr when empty.
  T* front() {
    const std::uint64_t read = read_.load(std::memory_order_relaxed);
    if (read == write_cache_) {
      write_cache_ = write_.load(std::memory_order_acquire);
      if (read == write_cache_) return nullptr;
    }
    return &slots_[read & mask_];
  }

  // Consumer: releases the slot returned by front() back to the producer.
  void pop() { read_.store(read_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // Consumer: sleeps until a slot is published, wake() is called, or `timeout_ns` passes.
  // Returns true when the ring is non-empty. It may return false early (a wake meant for an
  // earlier publish), so callers wait in a loop.
  bool wait(std::int64_t timeout_ns) {
    if (front() != nullptr) return true;
    const std::uint32_t seen = signal_.load(std::memory_order_acquire);
    sleeping_.store(true, std::memory_order_seq_cst);
    if (write_.load(std::memory_order_seq_cst) == read_.load(std::memory_order_relaxed)) {
      timespec ts{static_cast<time_t>(timeout_ns / 1'000'000'000),
                  static_cast<long>(timeout_ns % 1'000'000'000)};
      syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&signal_), FUTEX_WAIT_PRIVATE, seen, &ts,
              nullptr, 0);
    }
    sleeping_.store(false, std::memory_order_relaxed);
    return front() != nullptr;
  }

  // Any thread: wakes a consumer sleeping in wait().
  void wake() {
    signal_.fetch_add(1, std::memory_order_release);
    syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&signal_), FUTEX_WAKE_PRIVATE, 1, nullptr,
            nullptr, 0);
  }

  // Approximate number of published, unconsumed slots (exact when called by either side alone).
  std::size_t size() const {
    return static_cast<std::size_t>(write_.load(std::memory_order_acquire) -
                                    read_.load(std::memory_order_acquire));
  }

 private:
  static constexpr std::size_t kCacheLine = 64;
  static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t));

  std::vector<T> slots_;
  std::size_t mask_ = 0;

  alignas(kCacheLine) std::atomic<std::uint64_t> write_{0};  // written by the producer
  std::uint64_t read_cache_ = 0;                             // producer's copy of read_
  alignas(kCacheLine) std::atomic<std::uint64_t> read_{0};   // written by the consumer
  std::uint64_t write_cache_ = 0;                            // consumer's copy of write_
  alignas(kCacheLine) std::atomic<bool> sleeping_{false};
  std::atomic<std::uint32_t> signal_{0};
  char padding_[kCacheLine - sizeof(std::atomic<bool>) - sizeof(std::atomic<std::uint32_t>)]{};
};

}  // namespace laserline::daemon
