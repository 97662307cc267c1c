#include "tools/view_command_relay.hpp"

#include <laserline/command_t.hpp>

#include "lcmtypes/checked_decode.hpp"

namespace laserline::view {

namespace {

constexpr const char* kSettings[] = {"exposure_us",
                                     "gain_db",
                                     "frame_rate_hz",
                                     "laser.mode",
                                     "detector.maxvalue.threshold",
                                     "detector.frontend.snr_threshold_db",
                                     "detector.roi",
                                     "get"};
// A camera's own settings by name: GenICam features (aravis), V4L2 controls (v4l2).
constexpr const char* kCameraPrefixes[] = {"genicam:", "v4l2:"};

}  // namespace

std::string relay_problem(const std::string& name) {
  for (const char* setting : kSettings) {
    if (name == setting) return "";
  }
  for (const std::string prefix : kCameraPrefixes) {
    if (name.size() > prefix.size() && name.compare(0, prefix.size(), prefix) == 0) return "";
  }
  std::string printable = name;
  for (char& c : printable) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return "name: '" + printable +
         "' is not a setting the page sends (exposure_us, gain_db, frame_rate_hz, laser.mode, "
         "detector.maxvalue.threshold, detector.frontend.snr_threshold_db, detector.roi, "
         "genicam:<Feature>, v4l2:<control>, get)";
}

std::optional<laserline::command_ack_t> CommandRelay::send(const std::string& name,
                                                           const std::string& value,
                                                           std::chrono::milliseconds timeout) {
  laserline::command_t command;
  command.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                      std::chrono::system_clock::now().time_since_epoch())
                      .count();
  command.sender = "laserline-view";
  command.name = name;
  command.value = value;
  command.token = token_;
  std::unique_lock lock(mutex_);
  command.id = static_cast<std::int64_t>(random_() >> 1);
  waiting_[command.id];
  lock.unlock();
  lcm_.publish(channel_, &command);
  lock.lock();
  const bool answered = answered_.wait_for(
      lock, timeout, [&] { return waiting_[command.id].has_value() || stopping_; });
  std::optional<laserline::command_ack_t> ack = std::move(waiting_[command.id]);
  waiting_.erase(command.id);
  if (!answered) ack.reset();
  return ack;
}

void CommandRelay::on_ack(const lcm::ReceiveBuffer* rbuf) {
  laserline::command_ack_t ack;
  std::string problem;
  if (!laserline::messages::decode(rbuf->data, rbuf->data_size, &ack, {}, &problem)) return;
  {
    std::lock_guard lock(mutex_);
    const auto waiting = waiting_.find(ack.id);
    if (waiting == waiting_.end()) return;  // another sender's
    waiting->second = std::move(ack);
  }
  answered_.notify_all();
}

}  // namespace laserline::view
