#include "hal/laser_channel.hpp"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace laserline::hal {

bool LaserChannel::single() const {
  const int ones = (red == 1.0f) + (green == 1.0f) + (blue == 1.0f);
  const int zeros = (red == 0.0f) + (green == 0.0f) + (blue == 0.0f);
  return ones == 1 && zeros == 2;
}

namespace {

// A linear form c + r*red + g*green + b*blue.
struct Linear {
  double constant = 0, r = 0, g = 0, b = 0;
  bool is_constant() const { return r == 0 && g == 0 && b == 0; }
  Linear scaled(double k) const { return {constant * k, r * k, g * k, b * k}; }
  Linear plus(const Linear& o, double sign) const {
    return {constant + sign * o.constant, r + sign * o.r, g + sign * o.g, b + sign * o.b};
  }
};

// Recursive descent over: sum = product {(+|-) product}; product = unary {(*|/) unary};
// unary = [+|-] unary | number | name | ( sum ).
class Parser {
 public:
  explicit Parser(const std::string& text) : text_(text) {}

  Linear parse() {
    const Linear result = sum();
    skip_space();
    if (at_ < text_.size()) fail("unexpected '" + std::string(1, text_[at_]) + "'");
    return result;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw std::invalid_argument("channel \"" + text_ + "\": " + what + " at character " +
                                std::to_string(at_ + 1));
  }
  void skip_space() {
    while (at_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[at_])))
      ++at_;
  }
  bool take(char c) {
    skip_space();
    if (at_ < text_.size() && text_[at_] == c) {
      ++at_;
      return true;
    }
    return false;
  }

  Linear sum() {
    Linear value = product();
    while (true) {
      if (take('+')) {
        value = value.plus(product(), 1.0);
      } else if (take('-')) {
        value = value.plus(product(), -1.0);
      } else {
        return value;
      }
    }
  }

  Linear product() {
    Linear value = unary();
    while (true) {
      if (take('*')) {
        const Linear factor = unary();
        if (!value.is_constant() && !factor.is_constant()) {
          fail("a product of two channels is not a weighted sum");
        }
        value = value.is_constant() ? factor.scaled(value.constant) : value.scaled(factor.constant);
      } else if (take('/')) {
        const Linear divisor = unary();
        if (!divisor.is_constant()) fail("division by a channel is not a weighted sum");
        if (divisor.constant == 0) fail("division by zero");
        value = value.scaled(1.0 / divisor.constant);
      } else {
        return value;
      }
    }
  }

  Linear unary() {
    if (take('+')) return unary();
    if (take('-')) return unary().scaled(-1.0);
    if (take('(')) {
      const Linear inner = sum();
      if (!take(')')) fail("missing ')'");
      return inner;
    }
    skip_space();
    if (at_ >= text_.size()) fail("expression ends early");
    const char c = text_[at_];
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '.') {
      const char* begin = text_.c_str() + at_;
      char* end = nullptr;
      const double number = std::strtod(begin, &end);
      if (end == begin || !std::isfinite(number)) fail("bad number");
      at_ += static_cast<std::size_t>(end - begin);
      return {number, 0, 0, 0};
    }
    if (std::isalpha(static_cast<unsigned char>(c))) {
      const std::size_t start = at_;
      while (at_ < text_.size() && std::isalpha(static_cast<unsigned char>(text_[at_])))
        ++at_;
      const std::string name = text_.substr(start, at_ - start);
      if (name == "red" || name == "r") return {0, 1, 0, 0};
      if (name == "green" || name == "g") return {0, 0, 1, 0};
      if (name == "blue" || name == "b") return {0, 0, 0, 1};
      if (name == "grey" || name == "gray") return {0, 0.299, 0.587, 0.114};
      at_ = start;
      fail("unknown name '" + name + "' (red, green, blue, grey)");
    }
    fail("unexpected '" + std::string(1, c) + "'");
  }

  const std::string& text_;
  std::size_t at_ = 0;
};

}  // namespace

LaserChannel parse_laser_channel(const std::string& text) {
  const Linear form = Parser(text).parse();
  const std::string prefix = "channel \"" + text + "\": ";
  if (form.constant != 0) {
    throw std::invalid_argument(prefix +
                                "a constant term is not allowed (weights of red, green "
                                "and blue only)");
  }
  if (!(form.r > 0 || form.g > 0 || form.b > 0)) {
    throw std::invalid_argument(prefix +
                                "no channel has a positive weight: the laser would "
                                "never be brighter than 0");
  }
  constexpr double kMaxWeight = 16.0;
  if (std::abs(form.r) > kMaxWeight || std::abs(form.g) > kMaxWeight ||
      std::abs(form.b) > kMaxWeight) {
    throw std::invalid_argument(prefix + "weights must be within -16..16");
  }
  LaserChannel channel;
  channel.red = static_cast<float>(form.r);
  channel.green = static_cast<float>(form.g);
  channel.blue = static_cast<float>(form.b);
  channel.text = text;
  return channel;
}

}  // namespace laserline::hal
