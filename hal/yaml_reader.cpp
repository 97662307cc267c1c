#include "hal/yaml_reader.hpp"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/parser.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <map>
#include <sstream>

namespace laserline::hal {

namespace {

std::string format_number(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

std::string line_prefix(const std::string& source, const YAML::Mark& mark) {
  return mark.line >= 0 ? source + ":" + std::to_string(mark.line + 1) + ": " : source + ": ";
}

// A raw NUL byte is not text: yaml-cpp reads it as the end of the stream or as an odd escape.
void refuse_nul_bytes(const std::string& text, const std::string& source_name) {
  const std::size_t at = text.find('\0');
  if (at == std::string::npos) return;
  const auto line =
      1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n');
  const std::size_t line_start = text.rfind('\n', at);
  const std::size_t column = at - (line_start == std::string::npos ? 0 : line_start + 1) + 1;
  throw ConfigError(source_name + ":" + std::to_string(line) + ": a NUL byte (\\0) at column " +
                    std::to_string(column) + " (byte offset " + std::to_string(at) +
                    "): not a text file");
}

// Walks a parsed document once: depth, number of values, keys that are plain scalars, no NUL
// in any key or value. Aliases are walked each time they are used, so a few lines that refer to
// each other many times cannot hide a huge document; the walk stops at kMaxYamlValues.
class DocumentCheck {
 public:
  explicit DocumentCheck(std::string source) : source_(std::move(source)) {}

  void walk(const YAML::Node& node, int depth) {
    if (++values_ > kMaxYamlValues) {
      fail(node, "more than " + std::to_string(kMaxYamlValues) +
                     " keys and values (aliases counted each time they are used)");
    }
    if (node.IsScalar()) {
      if (node.Scalar().find('\0') != std::string::npos) {
        fail(node, "contains a NUL byte: \"" + node.Scalar() + "\"");
      }
      return;
    }
    if (!node.IsMap() && !node.IsSequence()) return;
    if (depth >= kMaxYamlDepth) {
      fail(node, "nested more than " + std::to_string(kMaxYamlDepth) + " levels deep");
    }
    if (node.IsSequence()) {
      std::size_t index = 0;
      for (const auto& element : node) {
        path_.push_back("[" + std::to_string(index++) + "]");
        walk(element, depth + 1);
        path_.pop_back();
      }
      return;
    }
    for (const auto& entry : node) {
      if (!entry.first.IsScalar()) {
        fail(entry.first, "a key must be a plain name, not a list, a mapping or empty");
      }
      const std::string& key = entry.first.Scalar();
      if (key.find('\0') != std::string::npos) {
        fail(entry.first, "the key \"" + key + "\" contains a NUL byte");
      }
      path_.push_back(key);
      ++values_;
      walk(entry.second, depth + 1);
      path_.pop_back();
    }
  }

 private:
  [[noreturn]] void fail(const YAML::Node& at, const std::string& problem) const {
    std::string path;
    for (const auto& part : path_)
      path += (path.empty() || part[0] == '[' ? "" : ".") + part;
    throw ConfigError(line_prefix(source_, at.Mark()) + (path.empty() ? "top level" : path) + ": " +
                      problem);
  }

  std::string source_;
  std::vector<std::string> path_;
  std::size_t values_ = 0;
};

const char* file_type(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a named pipe (FIFO)";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

std::string mebibytes(std::size_t bytes) {
  return format_number(static_cast<double>(bytes) / (1 << 20)) + " MiB";
}

}  // namespace

std::string escape_control_characters(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte != 0x7f) {
      out += c;
      continue;
    }
    switch (c) {
      case '\0':
        out += "\\0";
        break;
      case '\t':
        out += "\\t";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      default: {
        static const char kHex[] = "0123456789abcdef";
        out += "\\x";
        out += kHex[byte >> 4];
        out += kHex[byte & 15];
      }
    }
  }
  return out;
}

namespace {

// Notes where a document's first node is, if it has one. Used only to find a second document.
class FirstNodeFinder final : public YAML::EventHandler {
 public:
  bool found = false;
  YAML::Mark mark;

  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark& at, YAML::anchor_t) override { note(at); }
  void OnScalar(const YAML::Mark& at, const std::string&, YAML::anchor_t,
                const std::string&) override {
    note(at);
  }
  void OnSequenceStart(const YAML::Mark& at, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
    note(at);
  }
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark& at, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
    note(at);
  }
  void OnMapEnd() override {}

 private:
  void note(const YAML::Mark& at) {
    if (!found) mark = at;
    found = true;
  }
};

// Where a second document with content begins, if the stream has one. Not YAML::LoadAll: on some
// malformed streams (a lone ',') yaml-cpp 0.7 yields empty documents forever without consuming
// input, growing without bound (jbeder/yaml-cpp#1040, fixed after 0.7). Only two documents are
// read here, and an empty second one holds nothing that could be lost.
bool find_second_document(const std::string& text, YAML::Mark& mark) {
  std::istringstream stream(text);
  YAML::Parser parser(stream);
  FirstNodeFinder first;
  if (!parser.HandleNextDocument(first)) return false;
  FirstNodeFinder second;
  if (!parser.HandleNextDocument(second) || !second.found) return false;
  mark = second.mark;
  return true;
}

}  // namespace

ConfigError::ConfigError(const std::string& message)
    : std::runtime_error(escape_control_characters(message)) {}

YAML::Node load_yaml_text(const std::string& text, const std::string& source_name) {
  if (text.size() > kMaxYamlFileBytes) {
    throw ConfigError(source_name + ": larger than " + mebibytes(kMaxYamlFileBytes) +
                      ": not a configuration or calibration");
  }
  refuse_nul_bytes(text, source_name);
  YAML::Node root;
  YAML::Mark second_document;
  bool has_second_document = false;
  try {
    root = YAML::Load(text);
    has_second_document = find_second_document(text, second_document);
  } catch (const YAML::DeepRecursion& e) {
    // yaml-cpp's own guard against overflowing the stack, far beyond kMaxYamlDepth.
    throw ConfigError(line_prefix(source_name, e.mark) + "nested more than " +
                      std::to_string(kMaxYamlDepth) + " levels deep");
  } catch (const YAML::ParserException& e) {
    throw ConfigError(line_prefix(source_name, e.mark) + "not valid YAML: " + e.msg);
  }
  if (has_second_document) {
    // A second document would be ignored, and with it whatever the user meant by it.
    throw ConfigError(line_prefix(source_name, second_document) +
                      "a second YAML document (after '---'): only one is read, give all keys in "
                      "one");
  }
  if (!root || root.IsNull()) {
    throw ConfigError(source_name + ": has no keys (empty, or only comments)");
  }
  if (!root.IsMap()) {
    throw ConfigError(line_prefix(source_name, root.Mark()) +
                      "the top level must be a mapping of keys");
  }
  DocumentCheck(source_name).walk(root, 0);
  return root;
}

YAML::Node load_yaml_file(const std::string& path) {
  // Non-blocking: opening a named pipe must not wait for a writer.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) throw ConfigError(path + ": cannot be opened for reading: " + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat info {};
  if (::fstat(fd, &info) != 0) {
    throw ConfigError(path + ": cannot be read: " + std::strerror(errno));
  }
  if (!S_ISREG(info.st_mode)) {
    throw ConfigError(path + ": is " + file_type(info.st_mode) +
                      ", not a file: give a configuration or calibration file");
  }
  if (static_cast<std::uintmax_t>(info.st_size) > kMaxYamlFileBytes) {
    throw ConfigError(path + ": is " + std::to_string(info.st_size) + " bytes, more than the " +
                      std::to_string(kMaxYamlFileBytes) + " (" + mebibytes(kMaxYamlFileBytes) +
                      ") a configuration or calibration may have");
  }
  // Read one byte past the limit: a file growing while it is read is caught too.
  std::string text(kMaxYamlFileBytes + 1, '\0');
  std::size_t size = 0;
  while (size < text.size()) {
    const ssize_t n = ::read(fd, text.data() + size, text.size() - size);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw ConfigError(path + ": read error: " + std::strerror(errno));
    if (n == 0) break;
    size += static_cast<std::size_t>(n);
  }
  if (size > kMaxYamlFileBytes) {
    throw ConfigError(path + ": grew past " + mebibytes(kMaxYamlFileBytes) +
                      " while it was read: not a configuration or calibration");
  }
  text.resize(size);
  return load_yaml_text(text, path);
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
  if (!has(key) && node_.IsMap()) {
    // A value left empty is marked where the next token is: name the key's line instead. (A
    // YAML::Node is a reference: assigning one to another would write into the document.)
    for (const auto& entry : node_) {
      if (entry.first.IsScalar() && entry.first.Scalar() == key) {
        throw ConfigError(location(entry.first) + key_path(key) + ": " + problem);
      }
    }
  }
  throw ConfigError(location(has(key) ? node_[key] : node_) + key_path(key) + ": " + problem);
}

bool YamlMap::has(const std::string& key) const {
  return node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

bool YamlMap::given(const std::string& key) const {
  if (has(key)) return true;
  // `key:` with nothing after it: most likely a value forgotten or indented wrongly, not a wish
  // for the default.
  if (node_.IsMap() && node_[key].IsDefined())
    fail(key, "has no value (give one or leave the key out)");
  return false;
}

YAML::Node YamlMap::scalar(const std::string& key) const {
  YAML::Node value = node_[key];
  if (!value.IsScalar()) fail(key, "must be a single value, not a list or mapping");
  return value;
}

double YamlMap::number(const std::string& key, double fallback, double min, double max) {
  known_.insert(key);
  if (!given(key)) return fallback;
  return required_number(key, min, max);
}

double YamlMap::required_number(const std::string& key, double min, double max) {
  known_.insert(key);
  if (!given(key)) fail(key, "is required");
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
  if (!given(key)) return fallback;
  return required_integer(key, min, max);
}

std::int64_t YamlMap::required_integer(const std::string& key, std::int64_t min, std::int64_t max) {
  known_.insert(key);
  if (!given(key)) fail(key, "is required");
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
  if (!given(key)) return fallback;
  YAML::Node value = scalar(key);
  bool result = false;
  if (!YAML::convert<bool>::decode(value, result)) {
    fail(key, "must be true or false, got '" + value.Scalar() + "'");
  }
  return result;
}

std::string YamlMap::string(const std::string& key, const std::string& fallback) {
  known_.insert(key);
  if (!given(key)) return fallback;
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
  if (!given(key)) return {};
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
  if (!has(key) && node_.IsMap() && node_[key].IsDefined()) {
    fail(key, "is empty (give its keys, or leave the section out for the defaults)");
  }
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
