#include "hal/camera.hpp"

namespace laserline::hal {

const char* to_string(GrabStatus status) {
  switch (status) {
    case GrabStatus::kOk:
      return "ok";
    case GrabStatus::kTimeout:
      return "timeout";
    case GrabStatus::kError:
      return "error";
    case GrabStatus::kStopped:
      return "stopped";
  }
  return "unknown";
}

}  // namespace laserline::hal
