#include "tools/extract_inputs.hpp"

#include <laserline/calibration_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "daemon/calibration_message.hpp"
#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"
#include "tools/frame_channel.hpp"
#include "tools/natural_order.hpp"

namespace laserline::tools::extract {

namespace {

namespace fs = std::filesystem;

constexpr const char* kImageExtensions[] = {
    ".png", ".jpg", ".jpeg", ".jpe",  ".tif", ".tiff", ".bmp", ".dib", ".pgm", ".ppm",
    ".pbm", ".pnm", ".pxm",  ".webp", ".jp2", ".ras",  ".sr",  ".exr", ".hdr", ".pic"};
constexpr const char* kVideoExtensions[] = {".avi", ".mp4",  ".m4v", ".mov", ".mkv",  ".webm",
                                            ".mpg", ".mpeg", ".wmv", ".ogv", ".mjpg", ".mjpeg",
                                            ".flv", ".ts",   ".mts", ".3gp", ".h264", ".h265"};

std::string lower_extension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

template <std::size_t N>
bool has_extension(const fs::path& path, const char* const (&extensions)[N]) {
  const std::string ext = lower_extension(path);
  return std::any_of(std::begin(extensions), std::end(extensions),
                     [&](const char* e) { return ext == e; });
}

// LCM log files start every event with this sync word (big-endian), the first at offset 0.
bool is_lcm_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char magic[4] = {};
  if (!in.read(reinterpret_cast<char*>(magic), 4)) return false;
  return magic[0] == 0xED && magic[1] == 0xA1 && magic[2] == 0xDA && magic[3] == 0x01;
}

std::string id_text(std::int64_t id) {
  return laserline::hal::calibration_id_text(static_cast<std::uint64_t>(id));
}

// An image file: one frame, counted even when it cannot be read so that frame numbers follow
// the list of files. A damaged file (cut short, a failed CRC) is skipped whole: its decoder fills
// what is missing, and lines through the filled part would be false points.
void extract_image(Extractor& x, const std::string& path) {
  cv::Mat image;
  std::string problem;
  if (!laserline::tools::read_image_file(path, image, problem)) {
    x.unreadable_frame(path + ": " + problem + "; skipped");
    return;
  }
  x.frame(image, path);
}

void extract_video(Extractor& x, const std::string& path, std::size_t input, std::size_t inputs) {
  cv::VideoCapture video;
  try {
    video.open(path, cv::CAP_FFMPEG);
  } catch (const cv::Exception&) {
  }
  if (!video.isOpened()) {
    x.fail(path + ": not a readable video; skipped");
    return;
  }
  // Checked once here rather than once per frame.
  const int width = static_cast<int>(video.get(cv::CAP_PROP_FRAME_WIDTH));
  const int height = static_cast<int>(video.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (width > 0 && height > 0 && (width != x.width() || height != x.height())) {
    x.fail(path + ": video is " + std::to_string(width) + "x" + std::to_string(height) +
           " but the calibration is for " + std::to_string(x.width()) + "x" +
           std::to_string(x.height()) + "; skipped");
    return;
  }
  const double count = video.get(cv::CAP_PROP_FRAME_COUNT);
  cv::Mat frame;
  std::int64_t n = 0;
  const std::string name = fs::path(path).filename().string();
  while (true) {
    bool got = false;
    try {
      got = video.read(frame);
    } catch (const cv::Exception&) {
      got = false;
    }
    if (!got || x.done()) break;
    x.frame(frame, path + " frame " + std::to_string(n));
    ++n;
    x.progress().update(input, inputs, name, count > 0 ? static_cast<double>(n) / count : 0.0,
                        x.frames());
  }
  if (n == 0) {
    x.fail(path + ": no frame could be decoded");
  } else if (count > 0 && static_cast<double>(n) < count) {
    // The container's own count (its header or index) against what decoded: a file cut short or
    // a decode that failed midway ends the frames early without an error from OpenCV.
    char announced[32];
    std::snprintf(announced, sizeof announced, "%.0f", count);
    x.fail(path + ": only " + std::to_string(n) + " of the " + announced +
           " frames its container announces could be decoded (cut short or damaged?); those " +
           std::to_string(n) + " were processed");
  }
}

// An LCM log: every laserline.image_t message (on any channel) is a frame, in log order. The
// laser state of a frame comes from the profile_t of the same sequence number in the same log
// (image_t does not carry it); without one, from --laser-pattern (else on). Damaged records are
// skipped (reported with their byte offsets) and reading goes on at the next whole event; every
// message is decoded only after its lengths are checked (messages::decode). A log whose
// calibration_t or profiles name another calibration than the one in use is skipped whole.
void extract_log(Extractor& x, const std::string& path, std::size_t input, std::size_t inputs,
                 const CalibrationInUse& in_use) {
  using laserline::messages::LcmLogReader;
  const laserline::messages::Limits limits;
  std::map<std::int64_t, bool> laser_on_by_sequence;
  std::int64_t images = 0;
  LcmLogReader::Event event;
  LcmLogReader::Damage damage;
  std::string problem;
  {
    LcmLogReader log;
    if (!log.open(path, &problem)) {
      x.fail(problem + "; skipped");
      return;
    }
    laserline::profile_t profile;
    laserline::calibration_t calibration;
    std::string other_calibration;  // the first event naming another calibration
    while (log.next(&event, &damage)) {
      const std::int64_t hash =
          laserline::messages::message_hash(event.data.data(), event.data.size());
      std::optional<std::int64_t> named;
      if (hash == laserline::image_t::getHash()) {
        ++images;
      } else if (hash == laserline::profile_t::getHash() &&
                 laserline::messages::decode(event.data.data(), event.data.size(), &profile, limits,
                                             &problem)) {
        laser_on_by_sequence[profile.sequence] = profile.laser_on;
        named = profile.calibration_id;
      } else if (hash == laserline::calibration_t::getHash()) {
        if (laserline::messages::decode(event.data.data(), event.data.size(), &calibration, limits,
                                        &problem)) {
          named = calibration.calibration_id;
        } else {
          x.fail(path + " event " + std::to_string(event.number) + " (" + event.channel +
                 "): not a valid laserline.calibration_t: " + problem + "; skipped");
        }
      }
      if (named && static_cast<std::uint64_t>(*named) != in_use.id && other_calibration.empty()) {
        other_calibration = "event " + std::to_string(event.number) + " (" + event.channel +
                            ") names calibration " + id_text(*named);
      }
    }
    if (!other_calibration.empty() && !in_use.accept_others) {
      x.fail(path + ": " + other_calibration + ", not " +
             laserline::hal::calibration_id_text(in_use.id) + " of " + in_use.name +
             " in use; skipped (--override-log-calibration extracts it all the same)");
      return;
    }
  }
  if (images == 0) {
    x.fail(path + ": the LCM log holds no laserline.image_t message");
    return;
  }
  LcmLogReader log;
  if (!log.open(path, &problem)) {
    x.fail(problem + "; skipped");
    return;
  }
  const std::string name = fs::path(path).filename().string();
  std::int64_t n = 0;
  laserline::image_t message;
  cv::Mat image;
  while (true) {
    const bool more = log.next(&event, &damage);
    if (damage.bytes > 0) {
      const std::string range = "bytes " + std::to_string(damage.offset) + ".." +
                                std::to_string(damage.offset + damage.bytes - 1);
      x.fail(path + ": " + range +
             (more ? " are damaged (" + std::to_string(damage.records) +
                         " records); skipped, reading resumes at event " +
                         std::to_string(event.number)
                   : " are not a complete event (recording cut short?); ignored"));
    }
    if (!more || x.done()) break;
    if (laserline::messages::message_hash(event.data.data(), event.data.size()) !=
        laserline::image_t::getHash()) {
      continue;
    }
    const std::string where =
        path + " event " + std::to_string(event.number) + " (" + event.channel + ")";
    ++n;
    if (!laserline::messages::decode(event.data.data(), event.data.size(), &message, limits,
                                     &problem)) {
      x.unreadable_frame(where + ": not a valid laserline.image_t: " + problem + "; skipped");
    } else if (!laserline::messages::unpack_image(message, limits, cv::IMREAD_UNCHANGED, &image,
                                                  &problem)) {
      x.unreadable_frame(where + ": " + problem + "; skipped");
    } else {
      const auto state = laser_on_by_sequence.find(message.sequence);
      x.frame(
          image, where,
          state != laser_on_by_sequence.end() ? std::optional<bool>(state->second) : std::nullopt,
          message.utime);
    }
    x.progress().update(input, inputs, name, static_cast<double>(n) / static_cast<double>(images),
                        x.frames());
  }
  if (log.totals().damaged_regions > 0) {
    x.fail(path + ": " + log.damage_summary());
  }
}

// Image arguments are taken in the order given. When a run of them is not in natural order
// (a shell glob sorts step_num10.png before step_num2.png), says so once, before it starts.
void note_unnatural_order(Extractor& x, const std::vector<std::string>& inputs,
                          const std::vector<InputKind>& kinds, std::size_t first) {
  std::size_t end = first;
  while (end < inputs.size() && kinds[end] == InputKind::kImage)
    ++end;
  for (std::size_t i = first + 1; i < end; ++i) {
    if (!laserline::tools::natural_less(inputs[i], inputs[i - 1])) continue;
    x.progress().message("laserline-extract: note: the " + std::to_string(end - first) +
                         " image arguments from " + inputs[first] +
                         " on are not in natural order (" +
                         fs::path(inputs[i - 1]).filename().string() + " before " +
                         fs::path(inputs[i]).filename().string() +
                         "): frames are numbered in the order given; give their folder to read "
                         "them in natural order");
    return;
  }
}

// The image files of a folder, in natural order (empty with `ec` set when it cannot be listed).
std::vector<std::string> images_in_folder(const std::string& folder, std::error_code& ec) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (entry.is_regular_file(ec) && has_extension(entry.path(), kImageExtensions)) {
      files.push_back(entry.path());
    }
  }
  if (ec) return {};
  std::sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) {
    return laserline::tools::natural_less(a.filename().string(), b.filename().string());
  });
  std::vector<std::string> names;
  for (const auto& f : files)
    names.push_back(f.string());
  return names;
}

}  // namespace

InputKind kind_of(const std::string& input) {
  std::error_code ec;
  if (!fs::exists(input, ec)) return InputKind::kMissing;
  if (fs::is_directory(input, ec)) return InputKind::kFolder;
  if (is_lcm_log(input)) return InputKind::kLog;
  if (has_extension(input, kVideoExtensions)) return InputKind::kVideo;
  return InputKind::kImage;
}

LogCalibration first_log_calibration(const std::string& path) {
  using laserline::messages::LcmLogReader;
  LogCalibration found;
  LcmLogReader log;
  std::string problem;
  if (!log.open(path, &problem)) return found;  // reported when the log is extracted
  const laserline::messages::Limits limits;
  LcmLogReader::Event event;
  LcmLogReader::Damage damage;
  laserline::calibration_t message;
  laserline::profile_t profile;
  laserline::hal::Calibration calibration;
  while (log.next(&event, &damage)) {
    const std::int64_t hash =
        laserline::messages::message_hash(event.data.data(), event.data.size());
    const std::string where =
        path + " event " + std::to_string(event.number) + " (" + event.channel + ")";
    if (hash == laserline::calibration_t::getHash() &&
        laserline::messages::decode(event.data.data(), event.data.size(), &message, limits,
                                    &problem) &&
        laserline::daemon::calibration_from_message(message, &calibration, &problem)) {
      const auto id = static_cast<std::uint64_t>(message.calibration_id);
      if (found.where.empty()) {
        found.id = id;
        found.where = where;
      }
      if (found.id == id) found.calibration = calibration;
      return found;
    }
    if (found.where.empty() && hash == laserline::profile_t::getHash() &&
        laserline::messages::decode(event.data.data(), event.data.size(), &profile, limits,
                                    &problem)) {
      found.id = static_cast<std::uint64_t>(profile.calibration_id);
      found.where = where;
    }
  }
  return found;
}

void extract_inputs(Extractor& x, const std::vector<std::string>& inputs,
                    const std::vector<InputKind>& kinds, const CalibrationInUse& in_use) {
  for (std::size_t i = 0; i < inputs.size() && !x.done(); ++i) {
    const std::string& input = inputs[i];
    const std::size_t number = i + 1, count = inputs.size();
    const std::string name = fs::path(input).filename().string();
    x.start_input(input);
    switch (kinds[i]) {
      case InputKind::kMissing:
        // Not known to be a frame at all: takes no frame number.
        x.fail(input + ": no such file or folder; skipped");
        break;
      case InputKind::kFolder: {
        std::error_code ec;
        const std::vector<std::string> files = images_in_folder(input, ec);
        if (ec) {
          x.fail(input + ": folder cannot be listed: " + ec.message() + "; skipped");
          break;
        }
        if (files.empty()) {
          x.fail(input + ": folder holds no image file; skipped");
          break;
        }
        x.start_sequence();
        for (std::size_t k = 0; k < files.size() && !x.done(); ++k) {
          extract_image(x, files[k]);
          x.progress().update(number, count, name,
                              static_cast<double>(k + 1) / static_cast<double>(files.size()),
                              x.frames());
        }
        break;
      }
      case InputKind::kLog:
        x.start_sequence();
        extract_log(x, input, number, count, in_use);
        break;
      case InputKind::kVideo:
        x.start_sequence();
        extract_video(x, input, number, count);
        break;
      case InputKind::kImage:
        // Consecutive image arguments are one sequence (a shell glob).
        if (i == 0 || kinds[i - 1] != InputKind::kImage) {
          x.start_sequence();
          note_unnatural_order(x, inputs, kinds, i);
        }
        extract_image(x, input);
        x.progress().update(number, count, name, 1.0, x.frames());
        break;
    }
  }
}

}  // namespace laserline::tools::extract
