#include "daemon/command_server.hpp"

#include <laserline/command_ack_t.hpp>

#include <cstring>
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
      detector_options_(config.detector_options),
      submitted_roi_(config.detector_options.roi),
      problems_("laserlined: " + config.command_channel + ": "),
      refusals_("laserlined: ") {}

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
  pipeline::DetectorOptions options;
  if (!parse_command(message, config_, camera_, detector_options_, &command, &options, &reason)) {
    hal::write_setting_text(command.result.reason, reason.c_str());
    command.result.accepted = false;
    answer(command);
    return;
  }
  if (command.kind == CommandKind::kThreshold) {
    // The region last sent to the worker: it reaches the detector in place before this one.
    options.roi = submitted_roi_;
    std::unique_ptr<pipeline::Detector> detector;
    try {
      detector = pipeline::make_detector(config_.detector, options);
      detector->use_parts(path_.detection_parts());
      const hal::FrameFormat format = camera_.format();
      detector->reset(format.width, format.height);
    } catch (const std::exception& e) {
      hal::write_setting_line(command.result.reason, "%s: %s", command.setting.name, e.what());
      answer(command);
      return;
    }
    if (!path_.submit_detector(command, std::move(detector))) {
      hal::write_setting_line(command.result.reason,
                              "busy: a change of the detector is under way already");
      answer(command);
      return;
    }
    pending_options_ = options;
    return;
  }
  if (!path_.submit_command(command)) {
    hal::write_setting_line(command.result.reason,
                            "busy: %zu commands are waiting for the camera thread already",
                            FramePath::kCommandSlots);
    command.result.accepted = false;
    answer(command);
    return;
  }
  if (command.kind == CommandKind::kRegion) submitted_roi_ = command.region;
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

std::string CommandServer::region_in_force() const {
  const hal::FrameFormat format = camera_.format();
  return detector_options_.roi.in_frame(format.width, format.height).text();
}

void CommandServer::answer(const Command& given) {
  Command command = given;
  hal::SettingResult& r = command.result;
  // The detector's settings are known here, not on the threads that carried the command out.
  // Refused, the one in force stays and is answered as such.
  if (command.kind == CommandKind::kThreshold) {
    hal::write_setting_text(r.old_value,
                            threshold_value(config_.detector, detector_options_).c_str());
    if (r.accepted) detector_options_ = pending_options_;
    hal::write_setting_text(r.in_force,
                            threshold_value(config_.detector, detector_options_).c_str());
  } else if (command.kind == CommandKind::kRegion) {
    hal::write_setting_text(r.old_value, region_in_force().c_str());
    if (r.accepted) detector_options_.roi = command.region;  // as the worker read it back
    hal::write_setting_text(r.in_force,
                            r.accepted ? command.region.text().c_str() : region_in_force().c_str());
  } else if (command.kind == CommandKind::kGet && r.accepted) {
    const std::size_t used = std::strlen(r.in_force);
    hal::write_setting_line(std::span<char>(r.in_force).subspan(used), " %s=%s detector.roi=%s",
                            threshold_name(config_.detector),
                            threshold_value(config_.detector, detector_options_).c_str(),
                            region_in_force().c_str());
  }
  if (r.accepted && command.kind != CommandKind::kGet) {
    log(LogLevel::kInfo, "laserlined: command %lld from '%s': %s %s -> %s",
        static_cast<long long>(command.id), command.sender, command.setting.name, r.old_value,
        r.in_force);
  } else if (!r.accepted) {
    // At a limited rate per setting: a sender repeating a refused command cannot flood the log.
    refusals_.report(command.setting.name, "command " + std::to_string(command.id) + " from '" +
                                               command.sender + "' refused: " + r.reason);
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
