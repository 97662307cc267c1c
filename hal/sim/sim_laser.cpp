#include "hal/sim/sim_laser.hpp"

#include "hal/clock.hpp"

namespace laserline::hal {

SimLaser::~SimLaser() {
  on_.store(false, std::memory_order_release);
}

bool SimLaser::open(std::string* /*error*/) {
  on_.store(false, std::memory_order_release);
  return true;
}

bool SimLaser::set(bool on, std::uint64_t for_frame, LaserSwitch* record) {
  on_.store(on, std::memory_order_release);
  if (record != nullptr) *record = LaserSwitch{on, monotonic_ns(), for_frame};
  return true;
}

}  // namespace laserline::hal
