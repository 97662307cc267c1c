// libFuzzer: the calibration reader (hal/calibration.hpp) on any text. Its contract: a
// calibration is accepted or refused with hal::ConfigError; nothing else may escape.
#include <string>

#include "hal/calibration.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    laserline::hal::YamlMap map(laserline::hal::load_yaml_text(text, "fuzz.yaml"), "fuzz.yaml", "");
    laserline::hal::read_calibration(map);
  } catch (const laserline::hal::ConfigError&) {
  }
  return 0;
}
