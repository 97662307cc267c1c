#pragma once

#include <cstdint>
#include <string>

namespace laserline::daemon {

// Talks to systemd (Type=notify) over $NOTIFY_SOCKET with sd_notify(): READY once frames are
// being processed, a STATUS line, WATCHDOG pings only while the frame path makes progress (so a
// stalled pipeline is restarted by systemd's WatchdogSec=), and STOPPING on the way out. Without
// $NOTIFY_SOCKET (not run by systemd) every call does nothing.
// Thread context: the main thread only.
class ServiceNotifier {
 public:
  ServiceNotifier();

  // The watchdog interval systemd asked for ($WATCHDOG_USEC), 0 when there is none.
  std::int64_t watchdog_ns() const { return watchdog_ns_; }

  void ready(const std::string& status);
  void status(const std::string& status);
  // Pings the watchdog when `frames_processed` advanced since the last ping and half the
  // interval has passed; a frame path that processes nothing is not vouched for.
  void progress(std::int64_t frames_processed, std::int64_t now_mono_ns);
  void stopping(const std::string& status);

  std::int64_t watchdog_pings() const { return pings_; }

 private:
  void send(const std::string& state);

  std::int64_t watchdog_ns_ = 0;
  std::int64_t last_ping_ns_ = 0;
  std::int64_t frames_at_last_ping_ = 0;
  std::int64_t pings_ = 0;
  bool ready_ = false;
};

}  // namespace laserline::daemon
