#pragma once

#include <string>

struct gpiod_chip;
struct gpiod_line;

namespace laserline::hal {

// Where a GPIO line is: the chip as gpiod_chip_open_lookup takes it ("gpiochip0", "0", a path, a
// label), and the line's offset on it or, when the offset is -1, its name.
struct GpioLineAddress {
  std::string chip;
  int offset = -1;
  std::string line_name;
};

// Opens the chip and looks the line up: GPIO_GET_LINEINFO only, nothing is requested, so the
// line's level does not change. *line_desc names it for messages ("line 'STROBE' of gpiochip0
// (label)"). On failure, *chip is closed again and *why says in one line what is wrong.
bool find_gpio_line(const GpioLineAddress& address, gpiod_chip** chip, gpiod_line** line,
                    std::string* line_desc, std::string* why);

}  // namespace laserline::hal
