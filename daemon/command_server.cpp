#include "daemon/command_server.hpp"

#include <laserline/command_ack_t.hpp>

#include <vector>

#include "daemon/lcm_publisher.hpp"
#include "daemon/log.hpp"
#include "hal/clock.hpp"

namespace laserline::daemon {

namespace {

// How long a wait for a message lasts before the results are looked at again.
constexpr int kReceiveSliceMs = 20;

}  // namespace

CommandServer::CommandServer(const DaemonConfig& config, lcm::LCM& lcm, FramePath& path,
                             const hal::Camera& camera)
    : config_(config),
      lcm_(lcm),
      path_(path),
      camera_(camera),
      problems_("laserlined: " + config.command_channel + ": ") {}

CommandServer::~CommandServer() {
  stop();
}

bool CommandServer::start() {
  if (config_.lcm_url.rfind("file://", 0) == 0) return false;
  subscription_ = lcm_.subscribeFunction(config_.command_channel, &CommandServer::on_message, this);
  running_.store(true);
  thread_ = std::thread([this] { run(); });
  pthread_setname_np(thread_.native_handle(), "commands");
  return true;
}

void CommandServer::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
  lcm_.unsubscribe(subscription_);
  subscription_ = nullptr;
}

void CommandServer::on_message(const lcm::ReceiveBuffer* buffer, const std::string&,
                               CommandServer* self) {
  self->receive(*buffer);
}

void CommandServer::receive(const lcm::ReceiveBuffer& buffer) {
  laserline::command_t message;
  std::string problem;
  if (!messages::decode(buffer.data, buffer.data_size, &message, messages::Limits{}, &problem)) {
    path_.count_bad_command();
    problems_.report("bad message", "not a laserline.command_t: " + problem);
    return;
  }
  Command command;
  std::string reason;
  if (!parse_command(message, config_, camera_, &command, &reason)) {
    hal::write_setting_text(command.result.reason, reason.c_str());
    command.result.accepted = false;
    answer(command);
    return;
  }
  if (!path_.submit_command(command)) {
    hal::write_setting_line(command.result.reason,
                            "busy: %zu commands are waiting for the camera thread already",
                            FramePath::kCommandSlots);
    command.result.accepted = false;
    answer(command);
  }
}

void CommandServer::run() {
  Command done;
  while (running_.load(std::memory_order_relaxed)) {
    if (lcm_.handleTimeout(kReceiveSliceMs) < 0) {
      // The instance failed (its socket gone): the commands stop, the scanner goes on.
      log(LogLevel::kError, "laserlined: %s: cannot receive commands any more",
          config_.command_channel.c_str());
      break;
    }
    while (path_.take_command_result(&done))
      answer(done);
  }
}

void CommandServer::answer(const Command& command) {
  const hal::SettingResult& r = command.result;
  if (r.accepted && command.kind != CommandKind::kGet) {
    log(LogLevel::kInfo, "laserlined: command %lld from '%s': %s %s -> %s",
        static_cast<long long>(command.id), command.sender, command.setting.name, r.old_value,
        r.in_force);
  } else if (!r.accepted) {
    log(LogLevel::kWarning, "laserlined: command %lld from '%s' refused: %s",
        static_cast<long long>(command.id), command.sender, r.reason);
  }
  laserline::command_ack_t ack;
  ack.utime = hal::wall_ns() / 1000;
  ack.id = command.id;
  ack.name = command.setting.name;
  ack.accepted = r.accepted;
  ack.reason = r.accepted ? "" : r.reason;
  ack.value = r.in_force;
  ack.old_value = r.old_value;
  ack.instance_id = process_instance_id();
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(ack.getEncodedSize()));
  ack.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  lcm_.publish(config_.command_ack_channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

}  // namespace laserline::daemon
