#include "hal/gpio_strobe.hpp"

#include <gpiod.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>

namespace laserline::hal {

namespace {

std::string line_text(const GpioLineAddress& line) {
  return line.offset >= 0 ? std::to_string(line.offset) : "'" + line.line_name + "'";
}

}  // namespace

GpioStrobe::GpioStrobe(GpioStrobeOptions options)
    : options_(std::move(options)),
      history_(options_.history),
      description_("line " + line_text(options_.line) + " of chip '" + options_.line.chip + "'") {}

GpioStrobe::~GpioStrobe() {
  close();
}

std::string GpioStrobe::failure(const std::string& why) const {
  if (why.rfind("chip '", 0) == 0) return "strobe line " + line_text(options_.line) + " on " + why;
  return "strobe " + why;
}

bool GpioStrobe::probe(std::string* found, std::string* error) const {
  gpiod_chip* chip = nullptr;
  gpiod_line* line = nullptr;
  std::string desc;
  std::string why;
  if (!find_gpio_line(options_.line, &chip, &line, &desc, &why)) {
    if (error != nullptr) *error = failure(why);
    return false;
  }
  const bool used = gpiod_line_is_used(line);
  const char* consumer = gpiod_line_consumer(line);
  const std::string held_by = consumer != nullptr ? std::string(" by '") + consumer + "'" : "";
  gpiod_chip_close(chip);
  if (used) {
    if (error != nullptr) *error = "strobe " + desc + ": in use" + held_by;
    return false;
  }
  if (found != nullptr) *found = "strobe " + desc + ": free";
  return true;
}

bool GpioStrobe::open(std::string* error) {
  close();
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = why;
    close();
    return false;
  };
  std::string desc;
  std::string why;
  if (!find_gpio_line(options_.line, &chip_, &line_, &desc, &why)) return fail(failure(why));
  description_ = desc;
  const int flags = options_.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (gpiod_line_request_both_edges_events_flags(line_, options_.consumer.c_str(), flags) != 0) {
    const int e = errno;
    why = "strobe " + desc + ": cannot request its edge events: " + std::strerror(e);
    gpiod_line_update(line_);
    if (e == EBUSY && gpiod_line_consumer(line_) != nullptr) {
      why += std::string(" (held by '") + gpiod_line_consumer(line_) + "')";
    }
    line_ = nullptr;  // not ours to release
    return fail(why);
  }
  stop_fd_ = eventfd(0, EFD_CLOEXEC);
  if (stop_fd_ < 0) return fail("strobe " + desc + ": eventfd: " + std::strerror(errno));
  thread_ = std::thread([this] { read_loop(); });
  pthread_setname_np(thread_.native_handle(), "ll-strobe");
  return true;
}

void GpioStrobe::close() {
  if (thread_.joinable()) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t w = write(stop_fd_, &one, sizeof one);
    thread_.join();
  }
  if (stop_fd_ >= 0) {
    ::close(stop_fd_);
    stop_fd_ = -1;
  }
  if (line_ != nullptr) {
    gpiod_line_release(line_);
    line_ = nullptr;
  }
  if (chip_ != nullptr) {
    gpiod_chip_close(chip_);
    chip_ = nullptr;
  }
}

void GpioStrobe::read_loop() {
  pollfd fds[2] = {{gpiod_line_event_get_fd(line_), POLLIN | POLLPRI, 0}, {stop_fd_, POLLIN, 0}};
  gpiod_line_event events[16];
  while (true) {
    if (poll(fds, 2, -1) < 0) {
      if (errno == EINTR) continue;
      read_errors_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    if (fds[1].revents != 0) return;
    if ((fds[0].revents & (POLLERR | POLLNVAL | POLLHUP)) != 0 &&
        (fds[0].revents & (POLLIN | POLLPRI)) == 0) {
      read_errors_.fetch_add(1, std::memory_order_relaxed);
      return;  // the line's file is gone: no edge will come (the status says the strobe is silent)
    }
    const int n = gpiod_line_event_read_multiple(line_, events, 16);
    if (n < 0) {
      read_errors_.fetch_add(1, std::memory_order_relaxed);
      const timespec pause{0, 1'000'000};  // not a busy loop on a line that keeps failing
      nanosleep(&pause, nullptr);
      continue;
    }
    for (int i = 0; i < n; ++i) {
      const std::int64_t t =
          static_cast<std::int64_t>(events[i].ts.tv_sec) * 1'000'000'000 + events[i].ts.tv_nsec;
      if (events[i].event_type == GPIOD_LINE_EVENT_RISING_EDGE) {
        history_.begin(t);
      } else {
        history_.end(t);
      }
    }
  }
}

}  // namespace laserline::hal
