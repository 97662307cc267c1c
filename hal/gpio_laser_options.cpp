#include <cstdlib>

#include "hal/gpio_laser.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {

namespace {

// `key`: a line offset 0..511 or a line name.
void read_line(YamlMap& options, const std::string& key, int* offset, std::string* name) {
  const std::string line = options.string(key, "");
  char* end = nullptr;
  const long number = std::strtol(line.c_str(), &end, 10);
  if (!line.empty() && *end == '\0') {
    if (number < 0 || number > 511) options.fail(key, "offset must be 0..511, got " + line);
    *offset = static_cast<int>(number);
  } else {
    if (line.empty()) options.fail(key, "must not be empty");
    *name = line;
  }
}

}  // namespace

std::unique_ptr<Laser> create_gpio_laser(YamlMap& options) {
  GpioLaserOptions o;
  if (!options.has("chip")) options.fail("chip", "required for the gpiod laser (e.g. gpiochip0)");
  o.chip = options.string("chip", "");
  if (!options.has("line")) {
    options.fail("line", "required for the gpiod laser: a line offset or a line name");
  }
  read_line(options, "line", &o.offset, &o.line_name);
  o.active_low = options.boolean("active_low", o.active_low);
  o.consumer = options.string("consumer", o.consumer);
  if (o.consumer.empty() || o.consumer.size() > 31) {
    options.fail("consumer", "must be 1 to 31 characters (the kernel's limit)");
  }
  if (options.has("strobe_line")) {
    GpioLineAddress& strobe = o.strobe.line;
    read_line(options, "strobe_line", &strobe.offset, &strobe.line_name);
    strobe.chip = options.string("strobe_chip", o.chip);
    if (strobe.chip.empty()) options.fail("strobe_chip", "must not be empty");
    if (strobe.chip == o.chip && strobe.offset == o.offset && strobe.line_name == o.line_name) {
      options.fail("strobe_line", "is the laser's own line (laser.line)");
    }
    o.strobe.active_low = options.boolean("strobe_active_low", false);
    o.strobe.consumer = o.consumer;
  } else {
    for (const char* key : {"strobe_chip", "strobe_active_low"}) {
      if (options.has(key)) options.fail(key, "goes with laser.strobe_line, which is not given");
    }
  }
  return std::make_unique<GpioLaser>(o);
}

namespace {
const LaserBackendRegistration kGpiod{"gpiod", create_gpio_laser};
}  // namespace

}  // namespace laserline::hal
