#pragma once

#include <atomic>
#include <cstddef>
#include <string>
#include <thread>

#include "hal/exposure_strobe.hpp"
#include "hal/gpio_line.hpp"

namespace laserline::hal {

struct GpioStrobeOptions {
  GpioLineAddress line;
  bool active_low = false;  // the camera drives the line low while it exposes
  std::string consumer = "laserlined";
  std::size_t history = 64;  // exposures kept (a power of two)
};

// The camera's strobe (exposure-active) output on a GPIO input, through libgpiod 1.6: the line
// is requested for both edges' events, which the kernel timestamps (CLOCK_MONOTONIC since Linux
// 5.7) as they happen; a reader thread takes them in batches (gpiod_line_event_read_multiple,
// the kernel's queue holds 16) into the history without allocating. The active edge begins an
// exposure, the inactive one ends it (active_low: the kernel reports them the other way round
// already, as the line's logical value).
class GpioStrobe final : public ExposureStrobe {
 public:
  explicit GpioStrobe(GpioStrobeOptions options);
  ~GpioStrobe() override;
  GpioStrobe(const GpioStrobe&) = delete;
  GpioStrobe& operator=(const GpioStrobe&) = delete;

  bool open(std::string* error) override;
  void close() override;
  // Finds the line without requesting it (--check-config --probe), as GpioLaser::probe().
  bool probe(std::string* found, std::string* error) const;
  const ExposureHistory& history() const override { return history_; }
  const std::string& describe() const override { return description_; }
  pthread_t native_thread() override {
    return thread_.joinable() ? thread_.native_handle() : pthread_t{};
  }
  // Reads of the line's events that failed (counted; the reader carries on).
  std::int64_t read_errors() const { return read_errors_.load(std::memory_order_relaxed); }

 private:
  void read_loop();
  // "strobe line 'STROBE' on chip 'gpiochip9': ..." or "strobe line 'STROBE' of gpiochip0 ...".
  std::string failure(const std::string& why) const;

  GpioStrobeOptions options_;
  ExposureHistory history_;
  std::string description_;
  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  int stop_fd_ = -1;
  std::thread thread_;
  std::atomic<std::int64_t> read_errors_{0};
};

}  // namespace laserline::hal
