// The paper's front-end (Section III) at 2048x1536 mono8, single thread, beside a straightforward
// composition of stock OpenCV calls doing the same stages, in the same run:
//   frontend_stages_*: our fused stages after homography estimation (warp + subtract + width
//                      normalisation, band-pass, SNR, peaks with sub-pixel refinement)
//   naive_opencv_stages: warpPerspective, subtract, remap, boxFilter x4, absdiff, divide, and a
//                      per-column loop for the peaks
//   frontend_background_detector: the whole `background` detector, homography estimation included
//   frontend_background_threads/<n>: the same, its work split across n threads (the daemon's
//                      pipeline.worker_threads; wall time), worker_pool_stage/<n>: what handing
//                      one stage to them costs; frontend_background_serial_parallel:
//                      the same in two parts on one thread, its time inside the split stages
//                      (parallel_ms) and outside (serial_ms), and what Amdahl's law makes of them
//                      for 2, 4 and 8 threads (speedup_<n>)
//   frontend_fir_detector: the `fir` detector (no background subtraction)
//   frontend_fir_region/<percent>: `fir` searching the middle <percent> of the columns and rows
//   frontend_validation_stages/<association>: Section IV on the candidates `background` gives on
//                      the pier scenario (segments, chain codes or image patches, matching,
//                      back-projection), 0 = chain_code, 1 = image_features
//   frontend_backprojection_detector: the whole `backprojection` detector on the pier
//   frontend_search_image/<axes>, naive_search_image/<axes>: the search image of a laser beside
//                      the camera (rows: transposed) or turned (oblique: resampled), ours and
//                      OpenCV's (transpose, warpAffine)
//   frontend_made_detector/<axes>: `background` as the daemon makes it, the laser across the
//                      image (columns), beside the camera (rows) and turned 30 degrees (oblique)
// Run: build/default/bench/laserline_bench --benchmark_filter='frontend|naive'
#include <benchmark/benchmark.h>

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/worker_pool.hpp"
#include "hal/sim/sim_scene.hpp"
#include "pipeline/backprojection_detector.hpp"
#include "pipeline/detector.hpp"
#include "pipeline/frontend.hpp"
#include "pipeline/frontend_detectors.hpp"
#include "pipeline/search_axes.hpp"
#include "pipeline/subpixel.hpp"
#include "tools/evaluation.hpp"

namespace {

using namespace laserline;

constexpr int kWidth = 2048, kHeight = 1536;

// The `ambient` scenario of laserline-evaluate at 2048x1536 (a PTU sweeping a wall lit as brightly
// as the laser), without sway so that the homography between two frames is a pure tilt and exact:
// H = K R K^-1.
hal::SimSceneOptions bench_scene() {
  for (const tools::Scenario& s : tools::standard_scenarios(kWidth, kHeight)) {
    if (s.name != "ambient") continue;
    hal::SimSceneOptions scene = s.scene;
    scene.sway_m = 0;
    scene.sway_deg = 0;
    return scene;
  }
  std::abort();
}

pipeline::DetectorOptions bench_options() {
  pipeline::DetectorOptions o;
  o.geometry = daemon::scanner_geometry(bench_scene().calibration);
  return o;
}

// Two consecutive frames of that scan and the homography between them.
struct Frames {
  std::vector<std::uint8_t> previous, current;
  pipeline::Homography current_to_previous;

  Frames() {
    const hal::SimSceneOptions scene = bench_scene();
    hal::SimScene sim(scene);
    previous.resize(sim.format().bytes());
    current.resize(sim.format().bytes());
    sim.render(10, true, previous);
    sim.render(11, true, current);
    // Tilt of scan_rate / frame_rate about x between the frames.
    const double a = scene.scan_rate_deg_s / scene.frame_rate_hz * M_PI / 180.0;
    const hal::CameraIntrinsics& c = scene.calibration.camera;
    const cv::Matx33d k(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    const cv::Matx33d r(1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a));
    const cv::Matx33d h = k * r * k.inv();
    for (int i = 0; i < 9; ++i)
      current_to_previous.h(i) = h.val[i];
  }
};

const Frames& frames() {
  static const Frames f;
  return f;
}

pipeline::ImageView view(const std::vector<std::uint8_t>& pixels) {
  return {pixels.data(), kWidth, kHeight, kWidth};
}

void BM_frontend_stages_after_homography(benchmark::State& state) {
  const Frames& f = frames();
  const pipeline::DetectorOptions o = bench_options();
  pipeline::Frontend frontend(o.geometry, o.frontend);
  frontend.reset(kWidth, kHeight);
  pipeline::Profile profile(frontend.max_points(kWidth));
  for (auto _ : state) {
    frontend.set_frame_minus_background(view(f.current), view(f.previous), f.current_to_previous);
    frontend.find_candidates(profile);
    benchmark::DoNotOptimize(profile.points().data());
    benchmark::ClobberMemory();
  }
  state.counters["points"] = static_cast<double>(profile.size());
  state.counters["normalised_rows"] = frontend.rows().rows();
}
BENCHMARK(BM_frontend_stages_after_homography)->Unit(benchmark::kMillisecond);

// The same stages composed from stock OpenCV calls on float images, the way one would first
// write them. Maps and buffers are made once, outside the timing.
void BM_naive_opencv_stages(benchmark::State& state) {
  cv::setNumThreads(1);
  const Frames& f = frames();
  const pipeline::DetectorOptions o = bench_options();
  pipeline::Frontend reference(o.geometry, o.frontend);  // for the row mapping only
  const pipeline::RowNormalisation& rows = reference.rows();
  const int inner = 3, outer = 9;
  const int guard = inner / 2 + outer / 2, hn = o.frontend.noise_rows / 2;
  const int noise_columns = o.frontend.noise_columns;
  const float threshold = std::pow(10.0f, static_cast<float>(o.frontend.snr_threshold_db) / 20.0f);

  const cv::Mat previous(kHeight, kWidth, CV_8UC1, const_cast<std::uint8_t*>(f.previous.data()));
  const cv::Mat current(kHeight, kWidth, CV_8UC1, const_cast<std::uint8_t*>(f.current.data()));
  cv::Matx33d h;
  for (int i = 0; i < 9; ++i)
    h.val[i] = f.current_to_previous.h(i);
  cv::Mat map_x(rows.rows(), kWidth, CV_32FC1), map_y(rows.rows(), kWidth, CV_32FC1);
  for (int r = 0; r < rows.rows(); ++r) {
    for (int u = 0; u < kWidth; ++u) {
      map_x.at<float>(r, u) = static_cast<float>(u);
      map_y.at<float>(r, u) = rows.source_row(r);
    }
  }
  cv::Mat warped, cur_f, prev_f, diff, normalised, box_in, box_out, band, mag, box_n, box_g, noise,
      snr;
  pipeline::Profile profile(reference.max_points(kWidth));
  for (auto _ : state) {
    profile.clear();
    cv::warpPerspective(previous, warped, cv::Mat(h), current.size(),
                        cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
    current.convertTo(cur_f, CV_32F);
    warped.convertTo(prev_f, CV_32F);
    cv::subtract(cur_f, prev_f, diff);
    cv::max(diff, 0.0, diff);
    cv::remap(diff, normalised, map_x, map_y, cv::INTER_LINEAR);
    cv::boxFilter(normalised, box_in, CV_32F, cv::Size(1, inner));
    cv::boxFilter(normalised, box_out, CV_32F, cv::Size(1, outer));
    cv::subtract(box_in, box_out, band);
    mag = cv::abs(band);
    cv::boxFilter(mag, box_n, CV_32F, cv::Size(noise_columns, 2 * hn + 1), cv::Point(-1, -1),
                  false);
    cv::boxFilter(mag, box_g, CV_32F, cv::Size(noise_columns, 2 * guard + 1), cv::Point(-1, -1),
                  false);
    cv::subtract(box_n, box_g, noise);
    noise *= 1.0 / (noise_columns * 2 * (hn - guard));
    cv::max(noise, 1.0, noise);
    cv::divide(band, noise, snr);
    for (int u = 0; u < kWidth; ++u) {
      for (int r = 2; r < rows.rows() - 2; ++r) {
        const float s = snr.at<float>(r, u);
        if (s < threshold || !(s > snr.at<float>(r - 1, u) && s >= snr.at<float>(r + 1, u) &&
                               s > snr.at<float>(r - 2, u) && s >= snr.at<float>(r + 2, u))) {
          continue;
        }
        const float offset = pipeline::gaussian_offset(
            band.at<float>(r - 1, u), band.at<float>(r, u), band.at<float>(r + 1, u));
        pipeline::ProfilePoint p;
        p.u = u;
        p.v = static_cast<float>(rows.to_source(r + offset));
        p.snr_db = 20.0f * std::log10(s);
        profile.add(p);
      }
    }
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
}
BENCHMARK(BM_naive_opencv_stages)->Unit(benchmark::kMillisecond);

// The whole `background` detector per frame: homography estimation (feature tracking + RANSAC),
// the stages above, and the copy of the rows of the frame it keeps for the next one. Fed the two
// frames in turn.
void BM_frontend_background_detector(benchmark::State& state) {
  const Frames& f = frames();
  pipeline::BackgroundDetector detector(bench_options());
  detector.reset(kWidth, kHeight);
  pipeline::Profile profile(detector.max_points(kWidth, kHeight));
  detector.detect(view(f.previous), {0, true}, profile);
  std::uint64_t sequence = 1;
  for (auto _ : state) {
    detector.detect(view(sequence % 2 == 1 ? f.current : f.previous), {sequence, true}, profile);
    ++sequence;
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
  state.counters["inliers"] = detector.last_motion().inliers;
}
BENCHMARK(BM_frontend_background_detector)->Unit(benchmark::kMillisecond);

// Seconds of `clock` (a thread's own CPU time: what it worked, however busy the machine is).
double seconds(clockid_t clock) {
  timespec t{};
  clock_gettime(clock, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// A runner that times the stages it runs: the time inside run() on `clock`.
class TimedParts final : public pipeline::PartRunner {
 public:
  TimedParts(pipeline::PartRunner& runner, clockid_t clock) : runner_(runner), clock_(clock) {}
  int parts() const override { return runner_.parts(); }
  void run(pipeline::PartWork work) override {
    const double start = seconds(clock_);
    runner_.run(work);
    inside_ += seconds(clock_) - start;
  }
  double inside_s() const { return inside_; }

 private:
  pipeline::PartRunner& runner_;
  clockid_t clock_;
  double inside_ = 0;
};

// `background` as the daemon runs it: the detector made by make_detector(), its work shared by the
// worker and n - 1 helper threads.
void BM_frontend_background_threads(benchmark::State& state) {
  const Frames& f = frames();
  const int threads = static_cast<int>(state.range(0));
  daemon::WorkerPool pool(threads);
  pool.start();
  TimedParts timed(pool, CLOCK_MONOTONIC);
  const std::unique_ptr<pipeline::Detector> detector =
      pipeline::make_detector("background", bench_options());
  detector->use_parts(timed);
  detector->reset(kWidth, kHeight);
  pipeline::Profile profile(detector->max_points(kWidth, kHeight));
  detector->detect(view(f.previous), {0, true}, profile);
  std::uint64_t sequence = 1;
  const double inside_before = timed.inside_s();
  // Each frame's latency: on a machine other work shares, the least is what the threads give
  // when they have the cores to themselves.
  std::vector<double> latencies;
  latencies.reserve(1 << 16);
  for (auto _ : state) {
    const double start = seconds(CLOCK_MONOTONIC);
    detector->detect(view(sequence % 2 == 1 ? f.current : f.previous), {sequence, true}, profile);
    if (latencies.size() < latencies.capacity())
      latencies.push_back(seconds(CLOCK_MONOTONIC) - start);
    ++sequence;
    benchmark::DoNotOptimize(profile.points().data());
  }
  pool.stop();
  const auto frames_done = static_cast<double>(sequence - 1);
  state.counters["parallel_ms"] = 1e3 * (timed.inside_s() - inside_before) / frames_done;
  std::sort(latencies.begin(), latencies.end());
  state.counters["least_ms"] = 1e3 * latencies.front();
  state.counters["median_ms"] = 1e3 * latencies[latencies.size() / 2];
}
BENCHMARK(BM_frontend_background_threads)
    ->Arg(1)
    ->Arg(2)
    ->Arg(4)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// What handing one stage to the threads and waiting for them costs (an empty stage), the helpers
// spinning as they do between the stages of a frame.
void BM_worker_pool_stage(benchmark::State& state) {
  daemon::WorkerPool pool(static_cast<int>(state.range(0)));
  pool.start();
  int done = 0;
  auto work = [&](int part) {
    if (part == 0) ++done;
  };
  for (auto _ : state)
    pool.run(pipeline::PartWork(work));
  pool.stop();
  benchmark::DoNotOptimize(done);
}
BENCHMARK(BM_worker_pool_stage)->Arg(2)->Arg(4)->UseRealTime()->Unit(benchmark::kMicrosecond);

// The serial and the parallel part of `background` (Amdahl): two parts one after the other on this
// thread, its CPU time inside the split stages (the parallel part's work, with what splitting
// adds) and outside. With n threads at best serial + parallel / n.
void BM_frontend_background_serial_parallel(benchmark::State& state) {
  const Frames& f = frames();
  pipeline::SequentialParts two(2);
  TimedParts timed(two, CLOCK_THREAD_CPUTIME_ID);
  const std::unique_ptr<pipeline::Detector> detector =
      pipeline::make_detector("background", bench_options());
  detector->use_parts(timed);
  detector->reset(kWidth, kHeight);
  pipeline::Profile profile(detector->max_points(kWidth, kHeight));
  detector->detect(view(f.previous), {0, true}, profile);
  std::uint64_t sequence = 1;
  const double inside_before = timed.inside_s();
  const double start = seconds(CLOCK_THREAD_CPUTIME_ID);
  for (auto _ : state) {
    detector->detect(view(sequence % 2 == 1 ? f.current : f.previous), {sequence, true}, profile);
    ++sequence;
    benchmark::DoNotOptimize(profile.points().data());
  }
  const double total = seconds(CLOCK_THREAD_CPUTIME_ID) - start;
  const auto frames_done = static_cast<double>(sequence - 1);
  const double parallel = (timed.inside_s() - inside_before) / frames_done;
  const double serial = total / frames_done - parallel;
  state.counters["serial_ms"] = 1e3 * serial;
  state.counters["parallel_ms"] = 1e3 * parallel;
  for (const int n : {2, 4, 8}) {
    state.counters["speedup_" + std::to_string(n)] = (serial + parallel) / (serial + parallel / n);
  }
}
BENCHMARK(BM_frontend_background_serial_parallel)->Unit(benchmark::kMillisecond);

void BM_frontend_fir_detector(benchmark::State& state) {
  const Frames& f = frames();
  pipeline::FirDetector detector(bench_options());
  detector.reset(kWidth, kHeight);
  pipeline::Profile profile(detector.max_points(kWidth, kHeight));
  for (auto _ : state) {
    detector.detect(view(f.current), {}, profile);
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
}
BENCHMARK(BM_frontend_fir_detector)->Unit(benchmark::kMillisecond);

// `fir` searching a region of the frame (DetectionRegion): the middle half of the columns and of
// the rows (argument 50: a quarter of the frame), or the whole frame (100).
void BM_frontend_fir_region(benchmark::State& state) {
  const Frames& f = frames();
  pipeline::FirDetector detector(bench_options());
  detector.reset(kWidth, kHeight);
  const auto percent = static_cast<int>(state.range(0));
  const int width = kWidth * percent / 100, height = kHeight * percent / 100;
  detector.set_region({(kWidth - width) / 2, (kHeight - height) / 2, width, height});
  pipeline::Profile profile(detector.max_points(kWidth, kHeight));
  for (auto _ : state) {
    detector.detect(view(f.current), {}, profile);
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
}
BENCHMARK(BM_frontend_fir_region)->Arg(100)->Arg(50)->Arg(25)->Unit(benchmark::kMillisecond);

// The search image alone for the mountings below (the frame transposed, or resampled on a grid
// turned 30 degrees that holds the whole frame), beside OpenCV's transpose and warpAffine
// (bilinear, edge replicated) making the same image.
hal::SimSceneOptions scenario_scene(const char* scenario) {
  for (const tools::Scenario& s : tools::standard_scenarios(kWidth, kHeight))
    if (s.name == scenario) return s.scene;
  std::abort();
}

void BM_frontend_search_image(benchmark::State& state, const char* scenario) {
  const pipeline::ScannerGeometry geometry =
      daemon::scanner_geometry(scenario_scene(scenario).calibration);
  const pipeline::SearchAxes axes = pipeline::choose_search_axes(geometry);
  pipeline::SearchImage search;
  search.reset(axes, kWidth, kHeight);
  const Frames& f = frames();
  for (auto _ : state) {
    const pipeline::ImageView image = search.make(view(f.current));
    benchmark::DoNotOptimize(image.data);
    benchmark::ClobberMemory();
  }
  state.counters["pixels"] = static_cast<double>(axes.lines) * axes.length;
}
BENCHMARK_CAPTURE(BM_frontend_search_image, rows, "beside")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_frontend_search_image, oblique, "oblique")->Unit(benchmark::kMillisecond);

void BM_naive_search_image(benchmark::State& state, const char* scenario) {
  const pipeline::ScannerGeometry geometry =
      daemon::scanner_geometry(scenario_scene(scenario).calibration);
  const pipeline::SearchAxes axes = pipeline::choose_search_axes(geometry);
  const Frames& f = frames();
  const cv::Mat frame(kHeight, kWidth, CV_8UC1, const_cast<std::uint8_t*>(f.current.data()));
  cv::Mat out(axes.length, axes.lines, CV_8UC1);
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);  // one thread, as ours
  // Search (line, position) -> image: x = origin + line * line_step + position * along.
  const cv::Matx23d search_to_image(axes.line_step[0], axes.along[0], axes.origin[0],
                                    axes.line_step[1], axes.along[1], axes.origin[1]);
  for (auto _ : state) {
    if (axes.axis == pipeline::SearchAxis::kRows)
      cv::transpose(frame, out);
    else
      cv::warpAffine(frame, out, cv::Mat(search_to_image), out.size(),
                     cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REPLICATE);
    benchmark::DoNotOptimize(out.data);
    benchmark::ClobberMemory();
  }
  cv::setNumThreads(threads);
}
BENCHMARK_CAPTURE(BM_naive_search_image, rows, "beside")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_naive_search_image, oblique, "oblique")->Unit(benchmark::kMillisecond);

// `background` as the daemon makes it (make_detector: search axes, triangulation) over two
// consecutive frames of a scenario, in turn; `options` with the scenario's geometry. The share of
// frames that subtracted the previous frame less its own line into `line_removed`.
void run_made_detector(benchmark::State& state, const char* scenario,
                       pipeline::DetectorOptions options, double* line_removed = nullptr) {
  const hal::SimSceneOptions scene = scenario_scene(scenario);
  hal::SimScene sim(scene);
  std::vector<std::uint8_t> a(sim.format().bytes()), b(sim.format().bytes());
  sim.render(10, true, a);
  sim.render(11, true, b);
  options.geometry = daemon::scanner_geometry(scene.calibration);
  const std::unique_ptr<pipeline::Detector> detector =
      pipeline::make_detector("background", options);
  detector->reset(kWidth, kHeight);
  pipeline::Profile profile(detector->max_points(kWidth, kHeight));
  std::uint64_t sequence = 0, removed = 0;
  for (auto _ : state) {
    detector->detect(view(sequence % 2 == 0 ? a : b), {sequence, true}, profile);
    ++sequence;
    removed += profile.background_line_removed() ? 1 : 0;
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.counters["points"] = static_cast<double>(profile.size());
  if (line_removed != nullptr) {
    *line_removed =
        static_cast<double>(removed) / static_cast<double>(std::max<std::uint64_t>(sequence, 1));
  }
}

// The whole detector on a laser across the image (`clean`: epipolar lines along the columns),
// beside the camera (`beside`: along the rows, the frame transposed) and turned (`oblique`:
// sampled along slanted lines), to be compared.
void BM_frontend_made_detector(benchmark::State& state, const char* scenario) {
  run_made_detector(state, scenario, {});
}
BENCHMARK_CAPTURE(BM_frontend_made_detector, columns, "clean")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_frontend_made_detector, rows, "beside")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_frontend_made_detector, oblique, "oblique")->Unit(benchmark::kMillisecond);

// `background` with a still camera in daylight (`hover-daylight`): no earlier frame the scene moved
// away from, so the previous frame less its own line (argument 1) or none, the frame searched as
// it is (0): what taking the line out costs.
void BM_frontend_background_still_camera(benchmark::State& state) {
  pipeline::DetectorOptions options;
  options.background.remove_own_line = state.range(0) != 0;
  double line_removed = 0;
  run_made_detector(state, "hover-daylight", options, &line_removed);
  state.counters["line_removed"] = line_removed;
}
BENCHMARK(BM_frontend_background_still_camera)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond);

// The `pier` scenario of laserline-evaluate at 2048x1536: relief whose parallax leaves `background`
// many false candidates, so the validation has work to do.
hal::SimSceneOptions pier_scene() {
  for (const tools::Scenario& s : tools::standard_scenarios(kWidth, kHeight))
    if (s.name == "pier") return s.scene;
  std::abort();
}

// Consecutive frames of the pier, the candidates `background` finds in each, and the camera motion
// into each frame as the motion estimate gives it, for timing the validation alone.
struct ValidationFrames {
  static constexpr int kCount = 8;
  std::vector<std::vector<std::uint8_t>> pixels;
  std::vector<pipeline::Profile> candidates;
  std::vector<pipeline::PairMotion> motion;
  std::vector<pipeline::Homography> homography;

  ValidationFrames() {
    const hal::SimSceneOptions scene = pier_scene();
    hal::SimScene sim(scene);
    pipeline::DetectorOptions o;
    o.geometry = daemon::scanner_geometry(scene.calibration);
    pipeline::BackgroundDetector detector(o, /*estimate_camera_motion=*/true);
    detector.reset(kWidth, kHeight);
    pipeline::Profile profile(detector.max_points(kWidth, kHeight));
    for (int k = 0; k <= kCount; ++k) {
      pixels.emplace_back(sim.format().bytes());
      sim.render(10 + k, true, pixels.back());
      detector.detect(view(pixels.back()), {static_cast<std::uint64_t>(10 + k), true}, profile);
      if (k == 0) {  // the first frame only primes the detector
        pixels.pop_back();
        continue;
      }
      candidates.push_back(profile);
      const pipeline::MotionEstimate& e = detector.last_motion();
      pipeline::PairMotion m;
      m.valid = e.valid && e.camera.valid;
      m.rotation = e.camera.rotation;
      m.translation = e.camera.translation;
      m.relative_scale = e.camera.relative_scale;
      motion.push_back(m);
      homography.push_back(e.previous_to_current);
    }
  }
};

const ValidationFrames& validation_frames() {
  static const ValidationFrames f;
  return f;
}

// Section IV alone per frame (segmentation, association, back-projection), on the candidates of
// consecutive frames of the scan; includes copying the candidates into the profile it rewrites.
void BM_frontend_validation_stages(benchmark::State& state) {
  const ValidationFrames& f = validation_frames();
  pipeline::DetectorOptions o;
  o.geometry = daemon::scanner_geometry(pier_scene().calibration);
  o.validation.association = state.range(0) == 0 ? pipeline::SegmentAssociation::chain_code
                                                 : pipeline::SegmentAssociation::image_features;
  pipeline::LineValidator validator(o.geometry, o.validation);
  validator.reset(kWidth, kHeight, f.candidates[0].capacity());
  pipeline::Profile profile(f.candidates[0].capacity());
  std::size_t k = 0, segments = 0, tested = 0, frames = 0;
  for (auto _ : state) {
    profile = f.candidates[k];
    validator.validate(profile, f.motion[k], view(f.pixels[k]), &f.homography[k]);
    benchmark::DoNotOptimize(profile.points().data());
    segments += validator.segments().segments.size();
    for (const pipeline::LineSegment& s : validator.segments().segments)
      tested += s.tested ? 1 : 0;
    ++frames;
    k = (k + 1) % f.candidates.size();
  }
  state.SetLabel(state.range(0) == 0 ? "chain_code" : "image_features");
  state.counters["candidates"] = static_cast<double>(f.candidates[0].size());
  state.counters["segments"] = static_cast<double>(segments) / static_cast<double>(frames);
  state.counters["tested"] = static_cast<double>(tested) / static_cast<double>(frames);
}
BENCHMARK(BM_frontend_validation_stages)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The whole `backprojection` detector (motion with the essential matrix, `background`'s stages,
// validation), fed the consecutive frames of the scan in turn (the sequence restarts every
// ValidationFrames::kCount frames).
void BM_frontend_backprojection_detector(benchmark::State& state) {
  const ValidationFrames& f = validation_frames();
  pipeline::DetectorOptions o;
  o.geometry = daemon::scanner_geometry(pier_scene().calibration);
  pipeline::BackprojectionDetector detector(o);
  detector.reset(kWidth, kHeight);
  pipeline::Profile profile(detector.max_points(kWidth, kHeight));
  std::uint64_t sequence = 0;
  std::size_t valid = 0;
  for (auto _ : state) {
    const std::size_t k = sequence % f.pixels.size();
    detector.detect(view(f.pixels[k]), {sequence, true}, profile);
    ++sequence;
    benchmark::DoNotOptimize(profile.points().data());
    for (const pipeline::ProfilePoint& p : profile.points())
      valid += p.valid ? 1 : 0;
  }
  state.counters["valid_points"] = static_cast<double>(valid) / static_cast<double>(sequence);
}
BENCHMARK(BM_frontend_backprojection_detector)->Unit(benchmark::kMillisecond);

}  // namespace
