#include "hal/yaml_reader.hpp"

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

namespace laserline::hal {

namespace {

std::string format_number(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

}  // namespace

YAML::Node load_yaml_text(const std::string& text, const std::string& source_name) {
  try {
    YAML::Node root = YAML::Load(text);
    if (root.IsNull()) return YAML::Node(YAML::NodeType::Map);
    if (!root.IsMap()) {
      throw ConfigError(source_name + ":" + std::to_string(root.Mark().line + 1) +
                        ": the top level must be a mapping of keys");
    }
    return root;
  } catch (const YAML::ParserException& e) {
    throw ConfigError(source_name + ":" + std::to_string(e.mark.line + 1) +
                      ": not valid YAML: " + e.msg);
  }
}

YAML::Node load_yaml_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot be opened for reading");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw ConfigError(path + ": read error");
  return load_yaml_text(text.str(), path);
}

YamlMap::YamlMap(YAML::Node node, std::string source, std::string path)
    : node_(std::move(node)), source_(std::move(source)), path_(std::move(path)) {
  if (node_.IsDefined() && !node_.IsNull() && !node_.IsMap()) {
    throw ConfigError(location(node_) + (path_.empty() ? std::string("top level") : path_) +
                      ": must be a mapping of keys");
  }
  // YAML forbids a key twice in one mapping, but the parser keeps both and a lookup finds the
  // first: the line a user edited last could silently be ignored.
  if (node_.IsMap()) {
    std::map<std::string, int> first_line;
    for (const auto& entry : node_) {
      if (!entry.first.IsScalar()) continue;
      const std::string key = entry.first.Scalar();
      const auto [it, inserted] = first_line.emplace(key, entry.first.Mark().line + 1);
      if (!inserted) {
        throw ConfigError(location(entry.first) + key_path(key) + ": given twice (first on line " +
                          std::to_string(it->second) + ")");
      }
    }
  }
}

std::string YamlMap::key_path(const std::string& key) const {
  if (key.empty()) return path_;
  return path_.empty() ? key : path_ + "." + key;
}

std::string YamlMap::location(const YAML::Node& at) const {
  if (at.IsDefined() && at.Mark().line >= 0) {
    return source_ + ":" + std::to_string(at.Mark().line + 1) + ": ";
  }
  return source_ + ": ";
}

void YamlMap::fail(const std::string& key, const std::string& problem) const {
  YAML::Node at = has(key) ? node_[key] : node_;
  throw ConfigError(location(at) + key_path(key) + ": " + problem);
}

bool YamlMap::has(const std::string& key) const {
  return node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

YAML::Node YamlMap::scalar(const std::string& key) const {
  YAML::Node value = node_[key];
  if (!value.IsScalar()) fail(key, "must be a single value, not a list or mapping");
  return value;
}

double YamlMap::number(const std::string& key, double fallback, double min, double max) {
  known_.insert(key);
  if (!has(key)) return fallback;
  return required_number(key, min, max);
}

double YamlMap::required_number(const std::string& key, double min, double max) {
  known_.insert(key);
  if (!has(key)) fail(key, "is required");
  YAML::Node value = scalar(key);
  double result = 0;
  if (!YAML::convert<double>::decode(value, result) || !std::isfinite(result)) {
    fail(key, "must be a number, got '" + value.Scalar() + "'");
  }
  if (result < min || result > max) {
    fail(key, "must be between " + format_number(min) + " and " + format_number(max) + ", got " +
                  value.Scalar());
  }
  return result;
}

std::int64_t YamlMap::integer(const std::string& key, std::int64_t fallback, std::int64_t min,
                              std::int64_t max) {
  known_.insert(key);
  if (!has(key)) return fallback;
  return required_integer(key, min, max);
}

std::int64_t YamlMap::required_integer(const std::string& key, std::int64_t min, std::int64_t max) {
  known_.insert(key);
  if (!has(key)) fail(key, "is required");
  YAML::Node value = scalar(key);
  std::int64_t result = 0;
  if (!YAML::convert<std::int64_t>::decode(value, result)) {
    fail(key, "must be a whole number, got '" + value.Scalar() + "'");
  }
  if (result < min || result > max) {
    fail(key, "must be between " + std::to_string(min) + " and " + std::to_string(max) + ", got " +
                  value.Scalar());
  }
  return result;
}

bool YamlMap::boolean(const std::string& key, bool fallback) {
  known_.insert(key);
  if (!has(key)) return fallback;
  YAML::Node value = scalar(key);
  bool result = false;
  if (!YAML::convert<bool>::decode(value, result)) {
    fail(key, "must be true or false, got '" + value.Scalar() + "'");
  }
  return result;
}

std::string YamlMap::string(const std::string& key, const std::string& fallback) {
  known_.insert(key);
  if (!has(key)) return fallback;
  return scalar(key).Scalar();
}

std::string YamlMap::choice(const std::string& key, const std::string& fallback,
                            const std::vector<std::string>& choices) {
  std::string value = string(key, fallback);
  for (const auto& c : choices) {
    if (c == value) return value;
  }
  std::string list;
  for (const auto& c : choices)
    list += (list.empty() ? "" : ", ") + c;
  fail(key, "must be one of " + list + ", got '" + value + "'");
}

std::vector<double> YamlMap::numbers(const std::string& key,
                                     const std::vector<std::size_t>& sizes) {
  known_.insert(key);
  if (!has(key)) return {};
  YAML::Node list = node_[key];
  std::string expected;
  for (auto s : sizes)
    expected += (expected.empty() ? "" : " or ") + std::to_string(s);
  if (!list.IsSequence()) fail(key, "must be a list of " + expected + " numbers");
  bool size_ok = false;
  for (auto s : sizes)
    size_ok = size_ok || list.size() == s;
  if (!size_ok) {
    fail(key, "must have " + expected + " numbers, got " + std::to_string(list.size()));
  }
  std::vector<double> result;
  for (std::size_t i = 0; i < list.size(); ++i) {
    double v = 0;
    if (!list[i].IsScalar() || !YAML::convert<double>::decode(list[i], v) || !std::isfinite(v)) {
      fail(key, "element " + std::to_string(i) + " must be a number");
    }
    result.push_back(v);
  }
  return result;
}

YamlMap YamlMap::map(const std::string& key) {
  known_.insert(key);
  return YamlMap(has(key) ? node_[key] : YAML::Node(), source_, key_path(key));
}

YAML::Node YamlMap::node(const std::string& key) {
  known_.insert(key);
  return has(key) ? node_[key] : YAML::Node();
}

void YamlMap::finish() const {
  if (!node_.IsMap()) return;
  for (const auto& entry : node_) {
    const std::string key = entry.first.Scalar();
    if (known_.count(key) == 0) {
      std::string list;
      for (const auto& k : known_)
        list += (list.empty() ? "" : ", ") + k;
      throw ConfigError(location(entry.first) + key_path(key) +
                        ": unknown key (expected one of: " + list + ")");
    }
  }
}

}  // namespace laserline::hal
