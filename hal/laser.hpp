#pragma once

#include <cstdint>
#include <string>

namespace laserline::hal {

class ExposureStrobe;

// One laser switch, stamped right after the output changed (PX4 camera_trigger habit).
struct LaserSwitch {
  bool on = false;
  std::int64_t mono_ns = 0;     // host CLOCK_MONOTONIC of the switch
  std::uint64_t for_frame = 0;  // the frame sequence number the new state is meant for
};

// The laser output. A Class 3B hazard: implementations start with the output off and switch it
// off in their destructor. Thread context: set() may be called concurrently from the camera
// thread and the safety watchdog; implementations make that safe without blocking.
class Laser {
 public:
  virtual ~Laser() = default;

  virtual bool open(std::string* error) = 0;
  // For --check-config: finds the hardware and says in one line what it found (*found) without
  // driving it, or false with a one-line reason in *error. Without hardware (the simulated
  // laser): true and *found empty.
  virtual bool probe(std::string* found, std::string* error) {
    (void)error;
    if (found != nullptr) found->clear();
    return true;
  }
  // Switches the output; returns false when the hardware refused (the state is then unknown
  // and callers treat it as on until a later off succeeds).
  virtual bool set(bool on, std::uint64_t for_frame, LaserSwitch* record) = 0;
  virtual bool is_on() const = 0;
  // The camera's strobe output where it is wired to an input beside the laser
  // (hal/exposure_strobe.hpp), opened by its owner; nullptr where none is.
  virtual ExposureStrobe* strobe() { return nullptr; }
};

}  // namespace laserline::hal
