// libFuzzer: the navigation pose CSV that laserline-extract --poses reads (tools/point_cloud.hpp)
// on any text. Its contract: a pose log is accepted or refused with PointCloudError; nothing else
// may escape, and an accepted log answers every time and row (interpolated rotations unit).
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>

#include "tools/point_cloud.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const laserline::tools::PoseLog log = laserline::tools::PoseLog::parse(in, "fuzz.csv");
    laserline::tools::Pose pose;
    const double span = log.last_time() - log.first_time();
    for (int k = 0; k <= 8; ++k) {
      if (!log.at_time(log.first_time() + span * k / 8.0, pose)) continue;
      if (!(std::abs(pose.rotation.squaredNorm() - 1.0) < 1e-6))
        std::abort();  // a rotation that is not one
    }
    for (std::size_t i = 0; i <= log.size(); ++i)
      log.at_index(i, pose);
  } catch (const laserline::tools::PointCloudError&) {
  }
  return 0;
}
