#include "hal/gpio_laser.hpp"

#include <cstdlib>

#include "hal/yaml_reader.hpp"

namespace laserline::hal {

std::unique_ptr<Laser> create_gpio_laser(YamlMap& options) {
  GpioLaserOptions o;
  if (!options.has("chip")) options.fail("chip", "required for the gpiod laser (e.g. gpiochip0)");
  o.chip = options.string("chip", "");
  if (!options.has("line")) {
    options.fail("line", "required for the gpiod laser: a line offset or a line name");
  }
  const std::string line = options.string("line", "");
  char* end = nullptr;
  const long offset = std::strtol(line.c_str(), &end, 10);
  if (!line.empty() && *end == '\0') {
    if (offset < 0 || offset > 511) options.fail("line", "offset must be 0..511, got " + line);
    o.offset = static_cast<int>(offset);
  } else {
    if (line.empty()) options.fail("line", "must not be empty");
    o.line_name = line;
  }
  o.active_low = options.boolean("active_low", o.active_low);
  o.consumer = options.string("consumer", o.consumer);
  if (o.consumer.empty() || o.consumer.size() > 31) {
    options.fail("consumer", "must be 1 to 31 characters (the kernel's limit)");
  }
  return std::make_unique<GpioLaser>(o);
}

}  // namespace laserline::hal
