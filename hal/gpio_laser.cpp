#include "hal/gpio_laser.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>

#include "hal/clock.hpp"

namespace laserline::hal {

GpioLaser::GpioLaser(GpioLaserOptions options) : options_(std::move(options)) {
  pthread_mutexattr_t attr;
  pthread_mutexattr_init(&attr);
  pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT);
  pthread_mutexattr_settype(&attr, PTHREAD_MUTEX_RECURSIVE);
  pthread_mutex_init(&mutex_, &attr);
  pthread_mutexattr_destroy(&attr);
}

GpioLaser::~GpioLaser() {
  close();
  pthread_mutex_destroy(&mutex_);
}

void GpioLaser::close() {
  if (line_ != nullptr) {
    set(false, 0, nullptr);
    gpiod_line_release(line_);
    line_ = nullptr;
  }
  if (chip_ != nullptr) {
    gpiod_chip_close(chip_);
    chip_ = nullptr;
  }
}

bool GpioLaser::open(std::string* error) {
  close();
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = why;
    close();
    return false;
  };
  errno = 0;
  chip_ = gpiod_chip_open_lookup(options_.chip.c_str());
  if (chip_ == nullptr) {
    return fail("chip '" + options_.chip +
                "': cannot open: " + (errno != 0 ? std::strerror(errno) : "no such GPIO chip"));
  }
  const std::string chip_name =
      std::string(gpiod_chip_name(chip_)) + " (" + gpiod_chip_label(chip_) + ")";
  const unsigned lines = gpiod_chip_num_lines(chip_);
  std::string line_desc;
  if (options_.offset >= 0) {
    line_desc = "line " + std::to_string(options_.offset) + " of " + chip_name;
    if (static_cast<unsigned>(options_.offset) >= lines) {
      return fail(line_desc + ": the chip has only " + std::to_string(lines) + " lines (0.." +
                  std::to_string(lines - 1) + ")");
    }
    line_ = gpiod_chip_get_line(chip_, static_cast<unsigned>(options_.offset));
    if (line_ == nullptr) return fail(line_desc + ": " + std::strerror(errno));
  } else {
    line_desc = "line '" + options_.line_name + "' of " + chip_name;
    errno = 0;
    line_ = gpiod_chip_find_line(chip_, options_.line_name.c_str());
    if (line_ == nullptr) {
      return fail(line_desc + ": " +
                  (errno == ENOENT || errno == 0 ? "no line of that name" : std::strerror(errno)));
    }
  }
  const int flags = options_.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (gpiod_line_request_output_flags(line_, options_.consumer.c_str(), flags, 0) != 0) {
    const int e = errno;
    std::string why = line_desc + ": cannot request it as an output: " + std::strerror(e);
    gpiod_line_update(line_);
    if (e == EBUSY && gpiod_line_consumer(line_) != nullptr) {
      why += std::string(" (held by '") + gpiod_line_consumer(line_) + "')";
    }
    line_ = nullptr;  // not ours to release
    return fail(why);
  }
  on_.store(false, std::memory_order_release);
  return true;
}

bool GpioLaser::set(bool on, std::uint64_t for_frame, LaserSwitch* record) {
  if (line_ == nullptr) return !on;  // never opened: the line is not driven, so not on
  pthread_mutex_lock(&mutex_);
  const bool ok = gpiod_line_set_value(line_, on ? 1 : 0) == 0;
  // Stamped right after the ioctl returned: the level is on the pin by then.
  const std::int64_t switched = monotonic_ns();
  // A refused switch leaves the level unknown: report it as on, so that callers keep trying off.
  on_.store(ok ? on : true, std::memory_order_release);
  pthread_mutex_unlock(&mutex_);
  if (ok && record != nullptr) *record = LaserSwitch{on, switched, for_frame};
  return ok;
}

}  // namespace laserline::hal
