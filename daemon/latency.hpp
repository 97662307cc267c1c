#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

namespace laserline::daemon {

struct LatencySummary {
  std::int64_t samples = 0;
  double p50_ms = 0, p99_ms = 0, max_ms = 0;
};

// Latency figures without allocating after construction: exact percentiles over the current
// window (a fixed array of samples, dropped beyond capacity), and a 10 us histogram over the
// whole run. Thread context: one thread (the publisher).
class LatencyStats {
 public:
  explicit LatencyStats(std::size_t window_capacity)
      : window_(window_capacity), histogram_(kBins + 1, 0) {}

  void add(std::int64_t latency_ns) {
    if (window_size_ < window_.size()) window_[window_size_++] = latency_ns;
    const std::int64_t bin = std::clamp<std::int64_t>(latency_ns / kBinNs, 0, kBins);
    ++histogram_[static_cast<std::size_t>(bin)];
    ++total_;
    total_max_ns_ = std::max(total_max_ns_, latency_ns);
  }

  // Percentiles of the window since the last call, then starts a new window.
  LatencySummary take_window() {
    LatencySummary s;
    s.samples = static_cast<std::int64_t>(window_size_);
    if (window_size_ > 0) {
      auto begin = window_.begin();
      auto end = begin + static_cast<std::ptrdiff_t>(window_size_);
      s.p50_ms = nth(begin, end, 0.50) * 1e-6;
      s.p99_ms = nth(begin, end, 0.99) * 1e-6;
      s.max_ms = static_cast<double>(*std::max_element(begin, end)) * 1e-6;
    }
    window_size_ = 0;
    return s;
  }

  // Over the whole run, to the histogram's 10 us resolution (upper bin edge).
  LatencySummary total() const {
    LatencySummary s;
    s.samples = total_;
    s.p50_ms = total_percentile(0.50);
    s.p99_ms = total_percentile(0.99);
    s.max_ms = static_cast<double>(total_max_ns_) * 1e-6;
    return s;
  }

 private:
  static constexpr std::int64_t kBinNs = 10'000;
  static constexpr std::int64_t kBins = 200'000;  // 2 s; slower lands in the last bin

  template <typename It>
  static double nth(It begin, It end, double q) {
    const auto count = end - begin;
    auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(count - 1) + 0.5);
    std::nth_element(begin, begin + k, end);
    return static_cast<double>(*(begin + k));
  }

  double total_percentile(double q) const {
    if (total_ == 0) return 0;
    const auto rank = static_cast<std::int64_t>(q * static_cast<double>(total_ - 1)) + 1;
    std::int64_t seen = 0;
    for (std::size_t i = 0; i < histogram_.size(); ++i) {
      seen += histogram_[i];
      if (seen >= rank)
        return static_cast<double>((static_cast<std::int64_t>(i) + 1) * kBinNs) * 1e-6;
    }
    return static_cast<double>(total_max_ns_) * 1e-6;
  }

  std::vector<std::int64_t> window_;
  std::size_t window_size_ = 0;
  std::vector<std::int64_t> histogram_;
  std::int64_t total_ = 0;
  std::int64_t total_max_ns_ = 0;
};

}  // namespace laserline::daemon
