// A frame's work split in parts, so that several cores share one frame's detection (shorter
// latency at the same rate). pipeline/ has no threads: a detector calls its PartRunner with the
// work of one stage, and whoever owns the threads (daemon/worker_pool.hpp) runs the parts on them.
#pragma once

#include <utility>

namespace laserline::pipeline {

// The most parts a detector splits a frame into (each part has its own scratch buffers).
inline constexpr int kMaxParts = 8;

// A reference to a callable taking a part's index (not owning, no allocation).
class PartWork {
 public:
  template <class F>
  explicit PartWork(F& work)
      : object_(&work), call_([](void* object, int part) { (*static_cast<F*>(object))(part); }) {}
  void operator()(int part) const { call_(object_, part); }

 private:
  void* object_;
  void (*call_)(void*, int);
};

// Runs work(part) once for every part in [0, parts()), perhaps at the same time on different
// threads, and returns when every part has returned. The detectors write each part's results into
// memory of its own (columns, rows or features of its own), so that what they give is the same to
// the bit for any number of parts. run() must neither allocate, lock nor throw once running.
// Thread context: the thread that runs the detector.
class PartRunner {
 public:
  virtual ~PartRunner() = default;
  virtual int parts() const = 0;
  virtual void run(PartWork work) = 0;
};

// The parts one after another on the calling thread: a detector's default (one part), and what the
// tests compare a split against.
class SequentialParts final : public PartRunner {
 public:
  explicit SequentialParts(int parts = 1) : parts_(parts) {}
  int parts() const override { return parts_; }
  void run(PartWork work) override {
    for (int part = 0; part < parts_; ++part)
      work(part);
  }

 private:
  int parts_;
};

// `parts` parts one after another (at most kMaxParts), shared (they have no state): e.g. to size a
// detector as that many threads will run it.
inline PartRunner& sequential_parts(int parts) {
  static SequentialParts runners[kMaxParts] = {
      SequentialParts(1), SequentialParts(2), SequentialParts(3), SequentialParts(4),
      SequentialParts(5), SequentialParts(6), SequentialParts(7), SequentialParts(8)};
  static_assert(kMaxParts == 8);
  return runners[parts < 1 ? 0 : parts > kMaxParts ? kMaxParts - 1 : parts - 1];
}

// One part: every detector's runner until it is given one.
inline PartRunner& one_part() {
  return sequential_parts(1);
}

// Part `part` of `parts` of the items [0, count): [first, end), as even as can be.
inline std::pair<int, int> part_range(int count, int part, int parts) {
  const long long total = count;
  return {static_cast<int>(total * part / parts), static_cast<int>(total * (part + 1) / parts)};
}

}  // namespace laserline::pipeline
