#pragma once

#include <cstdint>
#include <string>
#include <vector>

// laserline-view's JSON, written by hand: numbers, strings, arrays of numbers.
namespace laserline::view {

void append_string(std::string& out, const std::string& text);
// `decimals` at most; trailing zeros dropped, non-finite values as null.
void append_number(std::string& out, double value, int decimals = 3);
void append_integer(std::string& out, std::int64_t value);

class JsonObject {
 public:
  JsonObject& integer(const char* key, std::int64_t value) {
    this->key(key);
    append_integer(out_, value);
    return *this;
  }
  JsonObject& number(const char* key, double value, int decimals = 3) {
    this->key(key);
    append_number(out_, value, decimals);
    return *this;
  }
  JsonObject& boolean(const char* key, bool value) {
    this->key(key);
    out_ += value ? "true" : "false";
    return *this;
  }
  JsonObject& string(const char* key, const std::string& value) {
    this->key(key);
    append_string(out_, value);
    return *this;
  }
  // Already JSON.
  JsonObject& raw(const char* key, const std::string& json) {
    this->key(key);
    out_ += json;
    return *this;
  }
  std::string str() const { return out_ + "}"; }

 private:
  void key(const char* name) {
    out_ += out_.size() > 1 ? ",\"" : "\"";
    out_ += name;
    out_ += "\":";
  }
  std::string out_ = "{";
};

// An array of numbers, `decimals` at most each.
std::string numbers(const std::vector<float>& values, int decimals);

}  // namespace laserline::view
