#include "tools/view_command_relay.hpp"

#include <laserline/command_t.hpp>

#include "lcmtypes/checked_decode.hpp"

namespace laserline::view {

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
