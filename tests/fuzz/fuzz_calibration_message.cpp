// libFuzzer: laserline.calibration_t through the checked decode (lcmtypes/checked_decode.hpp).
#include "tests/fuzz/fuzz_message.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz_message<laserline::calibration_t>(data, size);
}
