#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace laserline::hal {

// A configuration or calibration problem. what() is one line: "FILE:LINE: KEY: problem"; control
// characters in it (a NUL or a line break in a value, a file name) are shown escaped (\0, \n,
// \x1b), so that nothing cuts or splits the line.
class ConfigError : public std::runtime_error {
 public:
  explicit ConfigError(const std::string& message);
};

// `text` with its control characters escaped as C writes them (\0 \t \n \r, else \xNN).
std::string escape_control_characters(const std::string& text);

// What a configuration or calibration file may be: larger or deeper files are refused before or
// while they are read (a file grown by mistake, /dev/zero, a hostile file).
inline constexpr std::size_t kMaxYamlFileBytes = 1 << 20;
inline constexpr int kMaxYamlDepth = 32;               // nested mappings and lists
inline constexpr std::size_t kMaxYamlValues = 100000;  // keys and values, aliases each time used

// Loads a YAML file: only a regular file (not a directory, a device or a named pipe, which could
// block or never end) of at most kMaxYamlFileBytes, holding one YAML document whose top level is
// a mapping with at least one key, nested at most kMaxYamlDepth deep, without NUL bytes and with
// plain keys. Throws ConfigError naming the file (and line, and key) otherwise.
YAML::Node load_yaml_file(const std::string& path);
// The same checks on text already in memory, named `source_name` in messages.
YAML::Node load_yaml_text(const std::string& text, const std::string& source_name);

// Strict, typed reading of one YAML mapping. Every key read is remembered so that finish() can
// reject keys nobody asked for (a typo must not silently fall back to a default). Used at start-up
// only; errors are thrown as ConfigError with the file, the line and the full key path.
class YamlMap {
 public:
  YamlMap() = default;
  // `node` may be null/undefined (an absent section): every key then takes its default.
  YamlMap(YAML::Node node, std::string source, std::string path);

  bool has(const std::string& key) const;
  double number(const std::string& key, double fallback, double min, double max);
  double required_number(const std::string& key, double min, double max);
  std::int64_t integer(const std::string& key, std::int64_t fallback, std::int64_t min,
                       std::int64_t max);
  std::int64_t required_integer(const std::string& key, std::int64_t min, std::int64_t max);
  bool boolean(const std::string& key, bool fallback);
  std::string string(const std::string& key, const std::string& fallback);
  // A string that must be one of `choices`.
  std::string choice(const std::string& key, const std::string& fallback,
                     const std::vector<std::string>& choices);
  // A sequence of numbers whose length is one of `sizes`; absent -> empty.
  std::vector<double> numbers(const std::string& key, const std::vector<std::size_t>& sizes);
  // A nested mapping; absent -> an empty map whose keys all take defaults.
  YamlMap map(const std::string& key);
  // The raw node of a key the caller interprets itself (marks it as known).
  YAML::Node node(const std::string& key);

  // Throws for the first key that was never read.
  void finish() const;

  [[noreturn]] void fail(const std::string& key, const std::string& problem) const;
  std::string key_path(const std::string& key) const;
  const std::string& source() const { return source_; }

 private:
  YAML::Node scalar(const std::string& key) const;
  // has(), but a key given without a value is an error rather than absent.
  bool given(const std::string& key) const;
  std::string location(const YAML::Node& at) const;

  YAML::Node node_;
  std::string source_;
  std::string path_;
  std::set<std::string> known_;
};

}  // namespace laserline::hal
