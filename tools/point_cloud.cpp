#include "tools/point_cloud.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <initializer_list>
#include <sstream>

namespace laserline::tools {

namespace {

constexpr const char* kFieldNames[] = {"timestamp", "x", "y", "z", "qw", "qx", "qy", "qz"};
constexpr int kFields = 8;
// Navigation logs print quaternions with a few decimals: their norm is 1 only that closely.
constexpr double kQuaternionNormTolerance = 1e-3;
constexpr int kCountWidth = 20;          // digits reserved for the vertex count in the PLY header
constexpr std::size_t kPointBytes = 16;  // float x y z snr

std::string trim(const std::string& s) {
  const auto begin = s.find_first_not_of(" \t\r");
  if (begin == std::string::npos) return "";
  const auto end = s.find_last_not_of(" \t\r");
  return s.substr(begin, end - begin + 1);
}

std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> fields;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, ','))
    fields.push_back(trim(field));
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

bool parse_number(const std::string& text, double& value) {
  if (text.empty()) return false;
  char* end = nullptr;
  errno = 0;
  value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size() && errno == 0 && std::isfinite(value);
}

std::string number_text(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.6f", value);
  return buffer;
}

void append_le(std::vector<unsigned char>& out, float value) {
  const auto bits = std::bit_cast<std::uint32_t>(value);
  for (int i = 0; i < 4; ++i)
    out.push_back(static_cast<unsigned char>(bits >> (8 * i)));
}

}  // namespace

PoseLog PoseLog::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    throw PointCloudError(path + ": cannot be read: " + std::strerror(errno));
  }
  return parse(in, path);
}

PoseLog PoseLog::parse(std::istream& in, const std::string& path) {
  PoseLog log;
  log.path_ = path;
  std::string line;
  int number = 0;
  int previous_line = 0;
  bool first_content = true;
  while (std::getline(in, line)) {
    ++number;
    const std::string where = path + ":" + std::to_string(number) + ": ";
    if (trim(line).empty()) continue;
    const std::vector<std::string> fields = split_csv(line);
    double value = 0;
    if (first_content && !parse_number(fields.front(), value)) {
      first_content = false;  // a header line
      continue;
    }
    first_content = false;
    if (static_cast<int>(fields.size()) != kFields) {
      throw PointCloudError(where + "expected 8 fields timestamp,x,y,z,qw,qx,qy,qz, found " +
                            std::to_string(fields.size()));
    }
    std::array<double, kFields> v{};
    for (int i = 0; i < kFields; ++i) {
      if (!parse_number(fields[static_cast<std::size_t>(i)], v[static_cast<std::size_t>(i)])) {
        throw PointCloudError(where + kFieldNames[i] + " '" + fields[static_cast<std::size_t>(i)] +
                              "' is not a finite number");
      }
    }
    const double norm = std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]);
    if (std::abs(norm - 1.0) > kQuaternionNormTolerance) {
      throw PointCloudError(where + "quaternion qw,qx,qy,qz has norm " + number_text(norm) +
                            ", not 1");
    }
    const Row row{v[0],
                  Pose{{v[1], v[2], v[3]}, {v[4] / norm, v[5] / norm, v[6] / norm, v[7] / norm}}};
    if (!log.rows_.empty() && !(row.time > log.rows_.back().time)) {
      throw PointCloudError(
          where + "timestamp " + number_text(row.time) + " is not after the previous row's " +
          number_text(log.rows_.back().time) + " (line " + std::to_string(previous_line) + ")");
    }
    previous_line = number;
    log.rows_.push_back(row);
  }
  if (in.bad()) throw PointCloudError(path + ": read error: " + std::strerror(errno));
  if (log.rows_.empty()) {
    throw PointCloudError(path + ": no pose rows (expected timestamp,x,y,z,qw,qx,qy,qz)");
  }
  return log;
}

bool PoseLog::at_time(double t, Pose& pose) const {
  if (!(t >= first_time() && t <= last_time())) return false;
  const auto after = std::upper_bound(rows_.begin(), rows_.end(), t,
                                      [](double time, const Row& row) { return time < row.time; });
  if (after == rows_.end()) {  // t is the last row's time
    pose = rows_.back().pose;
    return true;
  }
  const Row& b = *after;
  const Row& a = *(after - 1);
  const double s = (t - a.time) / (b.time - a.time);
  pose.position = a.pose.position + s * (b.pose.position - a.pose.position);
  // The shorter way round (q and -q are the same rotation).
  pose.rotation = a.pose.rotation.slerp(s, b.pose.rotation);
  return true;
}

bool PoseLog::at_index(std::size_t index, Pose& pose) const {
  if (index >= rows_.size()) return false;
  pose = rows_[index].pose;
  return true;
}

PlyWriter::PlyWriter(const std::string& path, const std::string& comment) : path_(path) {
  file_ = std::fopen(path.c_str(), "wb");
  if (file_ == nullptr) {
    throw PointCloudError(path + ": cannot be written: " + std::strerror(errno));
  }
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) header += "comment " + comment + "\n";
  header += "element vertex ";
  count_offset_ = static_cast<long>(header.size());
  // The count is padded to a fixed width so that it can be rewritten in place.
  header += std::string(kCountWidth, ' ') + "\n";
  header +=
      "property float x\nproperty float y\nproperty float z\nproperty float "
      "scalar_snr\nend_header\n";
  if (std::fwrite(header.data(), 1, header.size(), file_) != header.size() || !commit()) {
    throw PointCloudError(path + ": cannot be written: " + std::strerror(errno));
  }
}

PlyWriter::~PlyWriter() {
  if (file_ != nullptr) {
    commit();
    std::fclose(file_);
  }
}

void PlyWriter::add(const Eigen::Vector3d& xyz, float snr) {
  for (float value :
       {static_cast<float>(xyz[0]), static_cast<float>(xyz[1]), static_cast<float>(xyz[2]), snr})
    append_le(pending_, value);
}

bool PlyWriter::commit() {
  if (std::fseek(file_, 0, SEEK_END) != 0) return false;
  if (!pending_.empty() &&
      std::fwrite(pending_.data(), 1, pending_.size(), file_) != pending_.size()) {
    return false;
  }
  const std::int64_t count = committed_ + static_cast<std::int64_t>(pending_.size() / kPointBytes);
  char digits[kCountWidth + 1];
  std::snprintf(digits, sizeof digits, "%-*lld", kCountWidth, static_cast<long long>(count));
  if (std::fseek(file_, count_offset_, SEEK_SET) != 0) return false;
  if (std::fwrite(digits, 1, kCountWidth, file_) != static_cast<std::size_t>(kCountWidth)) {
    return false;
  }
  if (std::fflush(file_) != 0) return false;
  committed_ = count;
  pending_.clear();
  return true;
}

}  // namespace laserline::tools
