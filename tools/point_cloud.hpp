#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <cstdio>
#include <istream>
#include <stdexcept>
#include <string>
#include <vector>

namespace laserline::tools {

// A bad pose log or point cloud file; what() is one line naming the file (and line).
class PointCloudError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Where the camera is in the world: X_world = R(rotation) * X_camera + position. The quaternion
// is a vectorisable fixed-size Eigen type (16-byte aligned): held in a std::vector, that is safe
// since C++17, whose allocator honours alignof (no EIGEN_MAKE_ALIGNED_OPERATOR_NEW needed).
struct Pose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // unit

  Eigen::Vector3d apply(const Eigen::Vector3d& camera_point) const {
    return rotation * camera_point + position;
  }
};

// Camera poses from a navigation log: CSV rows `timestamp,x,y,z,qw,qx,qy,qz` (seconds, metres,
// quaternion of the camera in the world frame), timestamps increasing; a header line is allowed.
class PoseLog {
 public:
  // Throws PointCloudError "FILE:LINE: problem" for the first bad row.
  static PoseLog load(const std::string& path);
  // The same from a stream; `name` stands for the file in messages.
  static PoseLog parse(std::istream& in, const std::string& name);

  const std::string& path() const { return path_; }
  std::size_t size() const { return rows_.size(); }
  double first_time() const { return rows_.front().time; }
  double last_time() const { return rows_.back().time; }

  // The pose at time t (seconds): position linear, rotation slerp between the rows around it.
  // False outside the log's time span.
  bool at_time(double t, Pose& pose) const;
  // The pose of data row `index` (0-based, header not counted). False past the last row.
  bool at_index(std::size_t index, Pose& pose) const;

 private:
  struct Row {
    double time;
    Pose pose;
  };
  std::string path_;
  std::vector<Row> rows_;
};

// A point cloud as binary little-endian PLY (float x y z, float scalar_snr in dB), as CloudCompare,
// MeshLab and PCL read it. The SNR is named with CloudCompare's "scalar_" prefix: CloudCompare
// then loads it as a scalar field called "snr" without asking (also on its command line), which
// it does not do for a property named plainly "snr". The vertex count in the header is brought up
// to date by every commit(), so the file is a complete PLY after each frame even if the program is
// interrupted later.
class PlyWriter {
 public:
  // Creates (truncates) the file; `comment` goes into the header. Throws PointCloudError.
  PlyWriter(const std::string& path, const std::string& comment);
  ~PlyWriter();
  PlyWriter(const PlyWriter&) = delete;
  PlyWriter& operator=(const PlyWriter&) = delete;

  void add(const Eigen::Vector3d& xyz, float snr);
  // Writes the points added since the last commit and the new count; false on a write error.
  bool commit();
  std::int64_t count() const { return committed_; }

 private:
  std::string path_;
  FILE* file_ = nullptr;
  std::vector<unsigned char> pending_;  // points not yet written, as in the file
  std::int64_t committed_ = 0;
  long count_offset_ = 0;  // where the count's digits start in the header
};

}  // namespace laserline::tools
