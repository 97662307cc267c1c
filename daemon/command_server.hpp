#pragma once

#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>

#include "daemon/command.hpp"
#include "daemon/config.hpp"
#include "daemon/frame_path.hpp"
#include "hal/camera.hpp"
#include "lcmtypes/checked_decode.hpp"

namespace laserline::daemon {

// Takes commands (laserline.command_t) on lcm.command_channel while the daemon runs and answers
// each on lcm.command_ack_channel: a command that does not parse or is out of range at once with
// its reason; any other once the camera thread carried it out (FramePath::submit_command), with
// the value read back from the device. A threshold change builds a new detector here (sized for
// the camera's frames, which allocates) and hands it to the worker (FramePath::submit_detector);
// it starts without the history of earlier frames the old one kept. A change of detector.roi goes
// to the worker, which sets it on the detector in place (only bounds: it keeps its history). Every
// change is logged with its old and new values, every refusal with its reason (at a limited rate
// per setting); a message that is no command_t is counted (status_t.bad_messages), reported at a
// limited rate and otherwise ignored.
//
// Its own thread receives (lcm handle) and answers; the instance is the daemon's, which the
// publisher thread publishes on meanwhile (LCM allows that). A file:// URL (the daemon writing a
// log) receives nothing: no commands then.
//
// Thread context: construct, start() and stop() from the owning (main) thread.
class CommandServer {
 public:
  CommandServer(const DaemonConfig& config, lcm::LCM& lcm, FramePath& path,
                const hal::Camera& camera);
  ~CommandServer();
  CommandServer(const CommandServer&) = delete;
  CommandServer& operator=(const CommandServer&) = delete;

  // False when the URL receives nothing (file://): no commands.
  bool start();
  void stop();

 private:
  static void on_message(const lcm::ReceiveBuffer* buffer, const std::string& channel,
                         CommandServer* self);
  void receive(const lcm::ReceiveBuffer& buffer);
  void run();
  void answer(const Command& given);
  // detector.roi in force, resolved to the camera's frame: "x,y,width,height".
  std::string region_in_force() const;

  const DaemonConfig& config_;
  lcm::LCM& lcm_;
  FramePath& path_;
  const hal::Camera& camera_;
  pipeline::DetectorOptions detector_options_;  // in force
  pipeline::DetectorOptions pending_options_;   // of the threshold change under way
  pipeline::DetectionRegion submitted_roi_;     // the last detector.roi sent to the worker
  lcm::Subscription* subscription_ = nullptr;
  messages::ProblemLog problems_;  // messages that are no command_t
  messages::ProblemLog refusals_;  // commands refused, by setting
  std::atomic<bool> running_{false};
  std::thread thread_;
};

}  // namespace laserline::daemon
