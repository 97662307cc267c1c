#pragma once

#include <pthread.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "hal/frame.hpp"
#include "hal/laser.hpp"

namespace laserline::hal {

// One exposure as the camera's strobe (exposure-active) output showed it, on the host
// CLOCK_MONOTONIC (the kernel's timestamps of the two edges).
struct ExposureInterval {
  std::uint64_t index = 0;  // exposures counted since the strobe was opened, from 0
  std::int64_t start_mono_ns = 0;
  std::int64_t end_mono_ns = 0;
};

// The last exposures seen on a strobe line: one writer (the strobe's reader thread), any number
// of readers (the camera thread), no lock and no allocation after construction. Each slot is a
// seqlock: a reader that raced the writer retries or, when the slot was overwritten, learns the
// exposure is gone.
class ExposureHistory {
 public:
  // `capacity`: a power of two; the exposures kept.
  explicit ExposureHistory(std::size_t capacity);

  // Writer: the active edge (exposure begins) and the inactive one (it ends). An end without a
  // start (the strobe was opened mid-exposure) is ignored; a second start replaces the first
  // (a missed end).
  void begin(std::int64_t mono_ns);
  void end(std::int64_t mono_ns);

  // Exposures completed so far: indices 0 .. completed() - 1, the last capacity() of them kept.
  std::uint64_t completed() const { return completed_.load(std::memory_order_acquire); }
  // Exposure `index`, false when it is not complete yet or already overwritten.
  bool get(std::uint64_t index, ExposureInterval* out) const;
  // Host time of the last edge of either kind; 0 before the first.
  std::int64_t last_edge_mono_ns() const { return last_edge_.load(std::memory_order_acquire); }
  std::size_t capacity() const { return mask_ + 1; }

 private:
  struct Slot {
    std::atomic<std::uint64_t> sequence{0};  // odd while written; 2 * (index + 1) when complete
    std::atomic<std::int64_t> start{0};
    std::atomic<std::int64_t> end{0};
  };
  std::unique_ptr<Slot[]> slots_;
  std::size_t mask_;
  std::atomic<std::uint64_t> completed_{0};
  std::atomic<std::int64_t> last_edge_{0};
  std::int64_t open_start_ = 0;  // writer only: the start of the exposure in progress, 0 = none
};

// Matches frames to strobe exposures (camera thread only).
//
// By order first, then by the camera's own clock: exposures and frames are one to one and in
// the same order, and at high frame rates with overlapped readout the next exposure has already
// ended when a frame arrives, so no host time alone can tell which exposure was a frame's. The
// first frame after start (or after frames stopped: restart()) takes the oldest exposure not yet
// taken that ended before the frame arrived. Every later frame takes the exposure whose start
// lies nearest to the last match's start plus the camera-time difference between the two frames
// (exact on the camera's clock, whatever frames were lost between them), within `tolerance_ns`.
// A frame without such an exposure (its edges missed, or not read yet) is not matched; after
// three in a row the order is taken again from the next frame.
class ExposureMatcher {
 public:
  // `camera_ns`, `arrival_mono_ns`: the frame's (FrameInfo). True and *out when matched.
  bool match(const ExposureHistory& history, std::int64_t camera_ns, std::int64_t arrival_mono_ns,
             std::int64_t tolerance_ns, ExposureInterval* out);
  // Frames stopped: the next frame is matched by order again, among exposures from now on.
  void restart(const ExposureHistory& history);

 private:
  bool anchored_ = false;
  std::uint64_t next_index_ = 0;  // the first exposure not yet taken
  std::int64_t last_camera_ns_ = 0;
  std::int64_t last_start_ns_ = 0;
  int misses_ = 0;
};

// The laser over one exposure, from the switches around it.
enum class LaserExposure : std::uint8_t {
  kOff,      // off from start to end
  kOn,       // on from start to end
  kMixed,    // switched during the exposure
  kUnknown,  // the exposure began before the oldest switch remembered
};

// The last switches of the laser (camera thread only, which makes them), for deciding the
// laser's state over an exposure. Before the first switch the laser was off (it is opened off).
class LaserSwitchHistory {
 public:
  void add(const LaserSwitch& record);
  LaserExposure during(std::int64_t start_mono_ns, std::int64_t end_mono_ns) const;

 private:
  static constexpr std::size_t kKept = 8;
  std::array<LaserSwitch, kKept> switches_{};
  std::size_t count_ = 0;  // total added
};

// The camera's strobe output wired to a GPIO input beside the laser (`laser.strobe_line`): a
// reader thread timestamps its edges into history(). Thread context: open()/close() from the
// setup thread; history() from any thread.
class ExposureStrobe {
 public:
  virtual ~ExposureStrobe() = default;
  // Requests the line for edge events and starts the reader. False with a one-line reason
  // naming the chip and the line.
  virtual bool open(std::string* error) = 0;
  virtual void close() = 0;
  virtual const ExposureHistory& history() const = 0;
  // E.g. "line 'STROBE' of gpiochip0 (pinctrl-bcm2711)", for messages.
  virtual const std::string& describe() const = 0;
  // The reader thread, for the owner to give it its priority; pthread_t{} when not open.
  virtual pthread_t native_thread() = 0;
};

// Each grabbed frame's exposure and laser state, decided on the camera thread that switches the
// laser and grabs. With a strobe and a frame matched to one of its exposures: exact, the switch
// times against the exposure's edges; a partly lit frame counts as lit, so that it never serves as
// a laser-off background. Otherwise the estimate: the camera's timestamp mapped to the host clock,
// against the last switch. Camera thread only.
class FrameLaserDecider {
 public:
  // `strobe`: nullptr without laser.strobe_line. Frames are matched within a quarter period.
  FrameLaserDecider(const ExposureStrobe* strobe, double frame_rate_hz);

  // A switch this thread made (LaserSwitch::for_frame: the grab it is for).
  void switched(const LaserSwitch& record);

  struct Decision {
    bool matched = false;      // to an exposure on the strobe
    bool late_switch = false;  // the frame's own switch came after its exposure began
  };
  // Grab `grab_index` arrived: sets info.laser_switch_mono_ns, exposure_start_mono_ns and
  // exposure_end_mono_ns (0 when not matched), and laser_on where the strobe decides it.
  Decision decide(FrameInfo& info, std::uint64_t grab_index);
  // Frames stopped (a timeout, an error): the next one is matched by order again.
  void frames_stopped();

 private:
  const ExposureStrobe* strobe_;
  std::int64_t tolerance_ns_;
  LaserSwitch last_switch_;
  LaserSwitchHistory switches_;
  ExposureMatcher matcher_;
};

// The strobe's health in one line into `out` (no allocation): "ok", or why frames fall back to
// the estimate (silent since start or for longer than three frame periods and a second, or
// `unmatched` of the `matched` + `unmatched` frames looked at not matched). Any thread.
void describe_strobe_health(const ExposureStrobe& strobe, double frame_rate_hz,
                            std::int64_t now_mono, std::int64_t matched, std::int64_t unmatched,
                            char* out, std::size_t size);

}  // namespace laserline::hal
