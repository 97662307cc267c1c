#include "hal/gpio_laser.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>

#include "hal/clock.hpp"
#include "hal/gpio_line.hpp"
#include "hal/gpio_strobe.hpp"

namespace laserline::hal {

GpioLaser::GpioLaser(GpioLaserOptions options) : options_(std::move(options)) {
  if (!options_.strobe.line.chip.empty()) strobe_ = std::make_unique<GpioStrobe>(options_.strobe);
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

bool find_gpio_line(const GpioLineAddress& address, gpiod_chip** chip, gpiod_line** line,
                    std::string* line_desc, std::string* why) {
  auto fail = [&](const std::string& what) {
    *why = what;
    if (*chip != nullptr) gpiod_chip_close(*chip);
    *chip = nullptr;
    *line = nullptr;
    return false;
  };
  errno = 0;
  *chip = gpiod_chip_open_lookup(address.chip.c_str());
  if (*chip == nullptr) {
    return fail("chip '" + address.chip +
                "': cannot open: " + (errno != 0 ? std::strerror(errno) : "no such GPIO chip"));
  }
  const std::string chip_name =
      std::string(gpiod_chip_name(*chip)) + " (" + gpiod_chip_label(*chip) + ")";
  const unsigned lines = gpiod_chip_num_lines(*chip);
  if (address.offset >= 0) {
    *line_desc = "line " + std::to_string(address.offset) + " of " + chip_name;
    if (static_cast<unsigned>(address.offset) >= lines) {
      return fail(*line_desc + ": the chip has only " + std::to_string(lines) + " lines (0.." +
                  std::to_string(lines - 1) + ")");
    }
    *line = gpiod_chip_get_line(*chip, static_cast<unsigned>(address.offset));
    if (*line == nullptr) return fail(*line_desc + ": " + std::strerror(errno));
  } else {
    *line_desc = "line '" + address.line_name + "' of " + chip_name;
    errno = 0;
    *line = gpiod_chip_find_line(*chip, address.line_name.c_str());
    if (*line == nullptr) {
      return fail(*line_desc + ": " +
                  (errno == ENOENT || errno == 0 ? "no line of that name" : std::strerror(errno)));
    }
  }
  return true;
}

bool GpioLaser::probe(std::string* found, std::string* error) {
  gpiod_chip* chip = nullptr;
  gpiod_line* line = nullptr;
  std::string line_desc;
  std::string why;
  if (!find_gpio_line(address(), &chip, &line, &line_desc, &why)) {
    if (error != nullptr) *error = why;
    return false;
  }
  // The line's strings live in the chip's memory: copied before it is closed.
  const char* name = gpiod_line_name(line);
  const std::string named =
      line_desc + (name != nullptr && options_.offset >= 0 ? std::string(" ('") + name + "')" : "");
  const bool used = gpiod_line_is_used(line);
  const char* consumer = gpiod_line_consumer(line);
  const std::string held_by =
      (consumer != nullptr ? std::string(" by '") + consumer + "'" : std::string()) +
      (consumer != nullptr && options_.consumer == consumer
           ? " (another laserlined runs with it: stop that one first)"
           : " (laserlined could not request it)");
  const bool output = gpiod_line_direction(line) == GPIOD_LINE_DIRECTION_OUTPUT;
  gpiod_chip_close(chip);
  if (used) {
    // The daemon's own request would fail with EBUSY.
    if (error != nullptr) {
      *error = named + ": in use" + held_by;
    }
    return false;
  }
  if (found != nullptr) {
    *found = named + ": free, now an " + (output ? "output" : "input") + " (not requested)";
  }
  std::string strobe_found;
  if (strobe_ != nullptr) {
    if (!strobe_->probe(&strobe_found, error)) return false;
    if (found != nullptr) *found += "; " + strobe_found;
  }
  return true;
}

bool GpioLaser::open(std::string* error) {
  close();
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = why;
    close();
    return false;
  };
  std::string line_desc;
  std::string why;
  if (!find_gpio_line(address(), &chip_, &line_, &line_desc, &why)) return fail(why);
  const int flags = options_.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (gpiod_line_request_output_flags(line_, options_.consumer.c_str(), flags, 0) != 0) {
    const int e = errno;
    why = line_desc + ": cannot request it as an output: " + std::strerror(e);
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
