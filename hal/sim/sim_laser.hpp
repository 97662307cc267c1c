#pragma once

#include <atomic>

#include "hal/laser.hpp"

namespace laserline::hal {

// The simulated scanner's laser: a flag the simulated camera reads at exposure time.
class SimLaser final : public Laser {
 public:
  ~SimLaser() override;
  bool open(std::string* error) override;
  bool set(bool on, std::uint64_t for_frame, LaserSwitch* record) override;
  bool is_on() const override { return on_.load(std::memory_order_acquire); }

 private:
  std::atomic<bool> on_{false};
};

}  // namespace laserline::hal
