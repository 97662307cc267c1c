#pragma once

#include <pthread.h>

#include <atomic>
#include <memory>
#include <string>

#include "hal/gpio_strobe.hpp"
#include "hal/laser.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace laserline::hal {

// Where the laser's enable line is and how it is driven.
struct GpioLaserOptions {
  std::string chip;         // as gpiod_chip_open_lookup takes it: "gpiochip0", "0", a path, a label
  int offset = -1;          // line offset on the chip, or -1 to find the line by `line_name`
  std::string line_name;    // the line's name in the device tree (used when offset is -1)
  bool active_low = false;  // the laser driver is enabled by a low level
  std::string consumer = "laserlined";  // shown by gpioinfo while we hold the line
  // The camera's strobe output (`laser.strobe_line`); strobe.line.chip empty = none wired.
  GpioStrobeOptions strobe;
};

class YamlMap;
// The gpiod backend's factory (hal/registry.hpp): chip, line, active_low and consumer from the
// `laser:` section, and the strobe's strobe_line, strobe_chip and strobe_active_low.
std::unique_ptr<Laser> create_gpio_laser(YamlMap& options);

// The laser's enable input on a GPIO output line, through libgpiod 1.6. open() requests the line
// as an output already at "off", so the laser is never on before the first frame asks for it;
// the destructor switches it off before releasing the line (the kernel keeps the last level of a
// released line, so releasing it "on" would leave the laser on).
//
// Thread context: set() is called from the camera thread, the safety watchdog (main thread) and
// the fatal-signal handler. A priority-inheriting recursive mutex held only around the one
// GPIOHANDLE_SET_LINE_VALUES ioctl serialises them: uncontended it is one atomic operation;
// contended, the holder inherits the real-time priority; recursive, so that a signal handler
// interrupting a set() on the same thread can still switch the laser off.
class GpioLaser final : public Laser {
 public:
  explicit GpioLaser(GpioLaserOptions options);
  ~GpioLaser() override;
  GpioLaser(const GpioLaser&) = delete;
  GpioLaser& operator=(const GpioLaser&) = delete;

  bool open(std::string* error) override;
  // Opens the chip and looks the line up without requesting it (its level stays as it is):
  // "line 2 of gpiochip0 (label) ('LASER_EN'): free, now an input (not requested)". A line
  // another process holds is an error: open() would fail. The strobe line likewise, after it.
  bool probe(std::string* found, std::string* error) override;
  bool set(bool on, std::uint64_t for_frame, LaserSwitch* record) override;
  bool is_on() const override { return on_.load(std::memory_order_acquire); }
  // The strobe line when one is configured; open() leaves it closed (--laser-off must not
  // depend on it): the daemon opens it before the camera.
  ExposureStrobe* strobe() override { return strobe_.get(); }

 private:
  void close();
  GpioLineAddress address() const {
    return GpioLineAddress{options_.chip, options_.offset, options_.line_name};
  }

  GpioLaserOptions options_;
  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  pthread_mutex_t mutex_;
  std::atomic<bool> on_{false};
  std::unique_ptr<GpioStrobe> strobe_;
};

}  // namespace laserline::hal
