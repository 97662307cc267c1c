// libFuzzer: the daemon's configuration reader (daemon/config.hpp) on any text. Its contract:
// a configuration is accepted or refused with hal::ConfigError; nothing else may escape.
#include <string>

#include "daemon/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    laserline::daemon::parse_config(laserline::hal::load_yaml_text(text, "fuzz.yaml"), "fuzz.yaml");
  } catch (const laserline::hal::ConfigError&) {
  }
  return 0;
}
