#include "daemon/service_notifier.hpp"

#include <systemd/sd-daemon.h>

namespace laserline::daemon {

ServiceNotifier::ServiceNotifier() {
  std::uint64_t usec = 0;
  // Keeps the environment: nothing else reads it, and tests inspect it.
  if (sd_watchdog_enabled(0, &usec) > 0) watchdog_ns_ = static_cast<std::int64_t>(usec) * 1000;
}

void ServiceNotifier::send(const std::string& state) {
  sd_notify(0, state.c_str());
}

void ServiceNotifier::ready(const std::string& status) {
  if (ready_) return;
  ready_ = true;
  send("READY=1\nSTATUS=" + status);
}

void ServiceNotifier::status(const std::string& status) {
  send("STATUS=" + status);
}

void ServiceNotifier::progress(std::int64_t frames_processed, std::int64_t now_mono_ns) {
  if (watchdog_ns_ == 0 || !ready_) return;
  if (frames_processed == frames_at_last_ping_) return;
  if (now_mono_ns - last_ping_ns_ < watchdog_ns_ / 2) return;
  send("WATCHDOG=1");
  last_ping_ns_ = now_mono_ns;
  frames_at_last_ping_ = frames_processed;
  ++pings_;
}

void ServiceNotifier::stopping(const std::string& status) {
  send("STOPPING=1\nSTATUS=" + status);
}

}  // namespace laserline::daemon
