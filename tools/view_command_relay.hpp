#pragma once

#include <laserline/command_ack_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <string>

namespace laserline::view {

// Whether `name` is one of the settings the page sends (laserlined's, see laserline-ctl --help):
// the view relays nothing else. Empty when it is, else the one line why not.
std::string relay_problem(const std::string& name);

// Sends the page's commands to the daemon and waits for their answers. Thread context: send()
// from the HTTP threads, on_ack() from the LCM thread.
class CommandRelay {
 public:
  CommandRelay(lcm::LCM& lcm, std::string channel, std::string token)
      : lcm_(lcm), channel_(std::move(channel)), token_(std::move(token)) {}

  // The daemon's answer, or none within `timeout`.
  std::optional<laserline::command_ack_t> send(const std::string& name, const std::string& value,
                                               std::chrono::milliseconds timeout);
  void on_ack(const lcm::ReceiveBuffer* rbuf);

  void stop() {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    answered_.notify_all();
  }

  bool token_is(const std::string& token) const { return token == token_; }

 private:
  lcm::LCM& lcm_;
  std::string channel_;
  std::string token_;
  std::mutex mutex_;
  std::condition_variable answered_;
  std::map<std::int64_t, std::optional<laserline::command_ack_t>> waiting_;
  std::mt19937_64 random_{std::random_device{}()};
  bool stopping_ = false;
};

}  // namespace laserline::view
