#include "hal/sim/sim_surface.hpp"

#include <algorithm>
#include <stdexcept>

namespace laserline::hal::sim {

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("SimScene: " + message);
}

namespace {

// Smooth value noise on a wrapping lattice of `spacing` texels, values in [-1, 1], added * amp.
void add_value_noise(std::vector<float>& dst, int spacing, float amp, Rng& rng) {
  const int n = kTextureSize;
  const int cells = n / spacing;
  std::vector<float> lattice(static_cast<std::size_t>(cells) * cells);
  for (float& x : lattice)
    x = static_cast<float>(rng.uniform(-1.0, 1.0));
  std::vector<float> weight(spacing);
  for (int i = 0; i < spacing; ++i) {
    const float f = static_cast<float>(i) / static_cast<float>(spacing);
    weight[i] = f * f * (3.0f - 2.0f * f);
  }
  for (int y = 0; y < n; ++y) {
    const int cy0 = y / spacing, cy1 = (cy0 + 1) % cells;
    const float wy = weight[y % spacing];
    const float* r0 = &lattice[static_cast<std::size_t>(cy0) * cells];
    const float* r1 = &lattice[static_cast<std::size_t>(cy1) * cells];
    float* out = &dst[static_cast<std::size_t>(y) * n];
    for (int x = 0; x < n; ++x) {
      const int cx0 = x / spacing, cx1 = (cx0 + 1) % cells;
      const float wx = weight[x % spacing];
      const float top = r0[cx0] + wx * (r0[cx1] - r0[cx0]);
      const float bottom = r1[cx0] + wx * (r1[cx1] - r1[cx0]);
      out[x] += amp * (top + wy * (bottom - top));
    }
  }
}

// Surface texture: multi-octave value noise plus hard-edged rectangles and discs, so that a

// Bright marks with sharp edges painted over the texture: paint strokes (thin segments) and shells
// (small ellipses), each texel inside taking the mark's albedo.
void paint_marks(std::vector<float>& albedo, const SimSceneOptions& o) {
  const double texel = o.texture_scale_m / kFinestSpacing;
  const double tile_m = kTextureSize * texel;
  const auto count = static_cast<int>(std::lround(o.marks_per_m2 * tile_m * tile_m));
  Rng rng(o.seed ^ 0x6d61726b73303031ULL);
  const int n = kTextureSize;
  for (int k = 0; k < count; ++k) {
    const double cx = rng.uniform(0.0, n), cy = rng.uniform(0.0, n);
    const double angle = rng.uniform(0.0, kPi);
    const double dx = std::cos(angle), dy = std::sin(angle);
    const auto value = static_cast<float>(o.marks_albedo * rng.uniform(0.6, 1.0));
    double half_length = 0, half_width = 0, half_height = 0;
    const bool stroke = rng.uniform() < 0.7;
    if (stroke) {
      half_length = 0.5 * rng.uniform(0.02, 0.08) / texel;  // 2 - 8 cm long
      half_width = 0.5 * rng.uniform(1.0, 3.0);             // 1 - 3 texels wide
    } else {
      half_length = rng.uniform(0.004, 0.01) / texel;  // shells: 8 - 20 mm across
      half_height = half_length * rng.uniform(0.5, 0.8);
    }
    const int reach = static_cast<int>(std::ceil(half_length + half_width + 1));
    for (int j = -reach; j <= reach; ++j) {
      for (int i = -reach; i <= reach; ++i) {
        // Texel centres relative to the mark's centre, in its own axes.
        const double px = std::floor(cx) + i + 0.5 - cx, py = std::floor(cy) + j + 0.5 - cy;
        const double along = px * dx + py * dy, across = -px * dy + py * dx;
        const bool inside = stroke
                                ? std::abs(along) <= half_length && std::abs(across) <= half_width
                                : (along * along) / (half_length * half_length) +
                                          (across * across) / (half_height * half_height) <=
                                      1.0;
        if (!inside) continue;
        const int x = (static_cast<int>(std::floor(cx)) + i) & (n - 1);
        const int y = (static_cast<int>(std::floor(cy)) + j) & (n - 1);
        albedo[static_cast<std::size_t>(y) * kTextureStride + x] = value;
      }
    }
  }
  // The copies of the first row and column after the last.
  for (int y = 0; y < kTextureStride; ++y) {
    albedo[static_cast<std::size_t>(y) * kTextureStride + n] =
        albedo[static_cast<std::size_t>(y & (n - 1)) * kTextureStride];
  }
  for (int x = 0; x < kTextureStride; ++x)
    albedo[static_cast<std::size_t>(n) * kTextureStride + x] = albedo[x];
}

}  // namespace

std::vector<float> make_texture(const SimSceneOptions& o) {
  const std::uint64_t seed = o.seed;
  const double contrast = o.texture_contrast;
  const int n = kTextureSize;
  Rng rng(seed ^ 0x7465787475726531ULL);
  std::vector<float> smooth(static_cast<std::size_t>(n) * n, 0.0f);
  float amp = 1.0f;
  for (int spacing = kFinestSpacing; spacing <= 128; spacing *= 2) {
    add_value_noise(smooth, spacing, amp, rng);
    amp *= 0.8f;
  }
  float peak = 1e-6f;
  for (float x : smooth)
    peak = std::max(peak, std::abs(x));

  std::vector<float> blobs(static_cast<std::size_t>(n) * n, 0.0f);
  const int count = 3500;
  for (int k = 0; k < count; ++k) {
    const int x0 = static_cast<int>(rng.uniform(0.0, n));
    const int y0 = static_cast<int>(rng.uniform(0.0, n));
    const double size_lo = kFinestSpacing, size_hi = 12.0 * kFinestSpacing;
    const int w = static_cast<int>(size_lo * std::pow(size_hi / size_lo, rng.uniform()));
    const int h = static_cast<int>(size_lo * std::pow(size_hi / size_lo, rng.uniform()));
    const float value =
        static_cast<float>((rng.uniform() < 0.5 ? -1.0 : 1.0) * rng.uniform(0.6, 1.0));
    const bool disc = rng.uniform() < 0.4;
    const int r2 = (w / 2) * (w / 2);
    for (int dy = 0; dy < (disc ? w : h); ++dy) {
      for (int dx = 0; dx < w; ++dx) {
        if (disc) {
          const int ox = dx - w / 2, oy = dy - w / 2;
          if (ox * ox + oy * oy > r2) continue;
        }
        const int x = (x0 + dx) & (n - 1), y = (y0 + dy) & (n - 1);
        blobs[static_cast<std::size_t>(y) * n + x] = value;
      }
    }
  }

  std::vector<float> albedo(static_cast<std::size_t>(kTextureStride) * kTextureStride);
  for (int y = 0; y < kTextureStride; ++y) {
    for (int x = 0; x < kTextureStride; ++x) {
      const std::size_t i = static_cast<std::size_t>(y & (n - 1)) * n + (x & (n - 1));
      const float noise = std::clamp(0.4f * smooth[i] / peak + blobs[i], -1.0f, 1.0f);
      albedo[static_cast<std::size_t>(y) * kTextureStride + x] =
          std::max(0.0f, 1.0f + static_cast<float>(contrast) * noise);
    }
  }
  if (o.marks_per_m2 > 0) paint_marks(albedo, o);
  return albedo;
}

void validate_checkerboard(const SimSceneOptions& o) {
  const SimSceneOptions::Checkerboard& board = o.checkerboard;
  require(board.columns >= 0 && board.rows >= 0, "checkerboard columns and rows must be >= 0");
  if (board.columns > 0 && board.rows > 0) {
    const double texel = o.texture_scale_m / kFinestSpacing;
    const double squares = board.square_m / texel;
    require(std::isfinite(squares) && squares >= 1 &&
                std::abs(squares - std::round(squares)) < 1e-6 * squares,
            "checkerboard square_m must be a whole number of texels (texture_scale_m / " +
                std::to_string(kFinestSpacing) + ")");
    // The board and its margin (one square each side) must fit in the half of the wrapping
    // texture tile around the surface point.
    const double reach = std::round(squares) * (std::max(board.columns, board.rows) + 3) / 2.0 +
                         std::max(std::abs(board.offset_x_m), std::abs(board.offset_y_m)) / texel;
    require(std::isfinite(reach) && reach <= kTextureSize / 2,
            "checkerboard with its margin and offset must lie within " +
                std::to_string(kTextureSize / 2) + " texels of the surface point");
    require(finite_nonneg(board.dark_albedo) && board.dark_albedo <= 1,
            "checkerboard dark_albedo must be within [0, 1]");
  }
}

// Paints the calibration checkerboard (if any) into the albedo tile. Texel i is the albedo at
// texture coordinate i (wrapping), and bilinear sampling puts an edge between texels i - 1 and i
// exactly at i - 1/2: the board's edges are laid on half-integers so its squares are exact.
void paint_checkerboard(std::vector<float>& albedo, const SimSceneOptions& o) {
  validate_checkerboard(o);
  const SimSceneOptions::Checkerboard& board = o.checkerboard;
  if (board.columns <= 0 || board.rows <= 0) return;
  const int square =
      static_cast<int>(std::lround(board.square_m * kFinestSpacing / o.texture_scale_m));
  const int squares_x = board.columns + 1, squares_y = board.rows + 1;
  // Board coordinate (in texels from the board's top-left edge) of texel 0's centre.
  const double texel = o.texture_scale_m / kFinestSpacing;
  const int origin_x =
      squares_x * square / 2 - static_cast<int>(std::lround(board.offset_x_m / texel));
  const int origin_y =
      squares_y * square / 2 - static_cast<int>(std::lround(board.offset_y_m / texel));
  const auto dark = static_cast<float>(board.dark_albedo);
  for (int y = 0; y < kTextureStride; ++y) {
    for (int x = 0; x < kTextureStride; ++x) {
      // The tile wraps: texel x stands for texture coordinate x or x - kTextureSize, whichever
      // is nearer 0 (the board lies within half a tile of it).
      const int sx = (x & (kTextureSize - 1)) < kTextureSize / 2
                         ? (x & (kTextureSize - 1))
                         : (x & (kTextureSize - 1)) - kTextureSize;
      const int sy = (y & (kTextureSize - 1)) < kTextureSize / 2
                         ? (y & (kTextureSize - 1))
                         : (y & (kTextureSize - 1)) - kTextureSize;
      // Texel centre in board coordinates is bx + 1/2: never on an edge (a multiple of square).
      const int bx = sx + origin_x, by = sy + origin_y;
      if (bx < -square || bx >= (squares_x + 1) * square || by < -square ||
          by >= (squares_y + 1) * square) {
        continue;  // outside board and margin: the texture stays
      }
      float value = 1.0f;  // margin
      if (bx >= 0 && bx < squares_x * square && by >= 0 && by < squares_y * square) {
        value = (bx / square + by / square) % 2 == 0 ? dark : 1.0f;
      }
      albedo[static_cast<std::size_t>(y) * kTextureStride + x] = value;
    }
  }
}

namespace {

// Shoulder of a relief feature at distance x beyond its top: 1 on the top, falling to 0 over
// `width` along half a cosine (smooth, with no tail). Its steepest slope is (pi / 2) / width.
double shoulder(double x, double width) {
  if (x <= 0) return 1.0;
  if (x >= width) return 0.0;
  return 0.5 * (1.0 + std::cos(kPi * x / width));
}

}  // namespace

// The relief tile: round bumps (a cosine dome), flat-topped posts (a disc with a shoulder) and
// elongated piles (a capsule with a shoulder), combined by their maximum so that no flank is
// steeper than the steepest feature's. Heights in metres at the lattice points.
std::vector<float> make_relief(const SimSceneOptions& o) {
  const int n = kReliefSize;
  const double period = n * kReliefCellM;
  std::vector<double> height(static_cast<std::size_t>(n) * n, 0.0);
  Rng rng(o.seed ^ 0x72656c6965663031ULL);
  const auto count = static_cast<int>(std::lround(o.relief_per_m2 * period * period));
  for (int k = 0; k < count; ++k) {
    const double cx = rng.uniform(0.0, period), cy = rng.uniform(0.0, period);
    const double amplitude = rng.uniform(o.relief_min_height_m, o.relief_height_m);
    const double width = amplitude * 0.5 * kPi / o.relief_max_slope * rng.uniform(1.0, 1.4);
    const double kind = rng.uniform();
    double half_length = 0, top = 0;  // capsule: a segment of 2 half_length, top half-width
    if (kind < 0.4) {
      // A round bump.
    } else if (kind < 0.65) {
      top = rng.uniform(0.02, 0.10);  // a post
    } else {
      half_length = rng.uniform(0.15, 0.6);  // a pile lying along the surface
      top = rng.uniform(0.0, 0.04);
    }
    const double angle = rng.uniform(0.0, kPi);
    const double dx = std::cos(angle), dy = std::sin(angle);
    const double reach = std::min(half_length + top + width, 0.45 * period);
    const int i0 = static_cast<int>(std::floor((cx - reach) / kReliefCellM));
    const int i1 = static_cast<int>(std::ceil((cx + reach) / kReliefCellM));
    const int j0 = static_cast<int>(std::floor((cy - reach) / kReliefCellM));
    const int j1 = static_cast<int>(std::ceil((cy + reach) / kReliefCellM));
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const double px = i * kReliefCellM - cx, py = j * kReliefCellM - cy;
        const double along = std::clamp(px * dx + py * dy, -half_length, half_length);
        const double ex = px - along * dx, ey = py - along * dy;
        const double h = amplitude * shoulder(std::sqrt(ex * ex + ey * ey) - top, width);
        double& cell = height[static_cast<std::size_t>(j & (n - 1)) * n + (i & (n - 1))];
        cell = std::max(cell, h);
      }
    }
  }
  std::vector<float> tile(static_cast<std::size_t>(kReliefStride) * kReliefStride);
  for (int y = 0; y < kReliefStride; ++y) {
    for (int x = 0; x < kReliefStride; ++x) {
      tile[static_cast<std::size_t>(y) * kReliefStride + x] =
          static_cast<float>(height[static_cast<std::size_t>(y & (n - 1)) * n + (x & (n - 1))]);
    }
  }
  return tile;
}

// Bilinear height of the relief tile at surface coordinates (x, y) in metres.
double relief_at(const float* relief, double x, double y) {
  const double gx = std::clamp(x / kReliefCellM, -1e9, 1e9);
  const double gy = std::clamp(y / kReliefCellM, -1e9, 1e9);
  const double fx0 = std::floor(gx), fy0 = std::floor(gy);
  const double fx = gx - fx0, fy = gy - fy0;
  const auto ix = static_cast<std::int64_t>(fx0) & (kReliefSize - 1);
  const auto iy = static_cast<std::int64_t>(fy0) & (kReliefSize - 1);
  const float* p = relief + iy * kReliefStride + ix;
  const double top = p[0] + fx * (p[1] - p[0]);
  const double bottom = p[kReliefStride] + fx * (p[kReliefStride + 1] - p[kReliefStride]);
  return top + fy * (bottom - top);
}
std::vector<float> make_caustics(std::uint64_t seed, double caustic_peak, float& mean) {
  const int n = kCausticSize;
  Rng rng(seed ^ 0x636175737469637aULL);
  std::vector<float> smooth(static_cast<std::size_t>(n) * n, 0.0f);
  float amp = 1.0f;
  for (int spacing = n / kCausticCells; spacing >= n / kCausticCells / 4; spacing /= 2) {
    add_value_noise(smooth, spacing, amp, rng);
    amp *= 0.5f;
  }
  float peak = 1e-6f;
  for (float x : smooth)
    peak = std::max(peak, std::abs(x));
  // Bright where the noise crosses zero: thin curves that close into cells, as light focused by a
  // wavy water surface does.
  constexpr float kHalfWidth = 0.035f;
  std::vector<float> tile(static_cast<std::size_t>(kTextureStride) * kTextureStride);
  double sum = 0;
  for (int y = 0; y < kTextureStride; ++y) {
    for (int x = 0; x < kTextureStride; ++x) {
      const float z = std::abs(smooth[static_cast<std::size_t>(y & (n - 1)) * n + (x & (n - 1))]) /
                      peak / kHalfWidth;
      const float ridge = std::max(0.0f, 1.0f - z);
      const float value = ridge * ridge;
      tile[static_cast<std::size_t>(y) * kTextureStride + x] = value;
      if (x < n && y < n) sum += value;
    }
  }
  mean = static_cast<float>(sum / (static_cast<double>(n) * n));
  if (caustic_peak * mean <= 1.0) return tile;

  // The light base + gain * pattern, of mean 1 and brightest caustic_peak, has base = 1 - (peak -
  // 1) m / (1 - m), m the pattern's mean: negative beyond caustic_peak = 1 / m (some 30 to 55, by
  // the seed). Brighter curves must be thinner: the pattern is raised to the power k > 1 that
  // brings its mean to 1 / caustic_peak (no light between the curves, as at caustic_peak = 1 / m),
  // found by bisection over the texels on a curve.
  std::vector<float> lit;
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      const float value = tile[static_cast<std::size_t>(y) * kTextureStride + x];
      if (value > 0) lit.push_back(value);
    }
  }
  const double texels = static_cast<double>(n) * n;
  auto mean_at = [&](double k) {
    double s = 0;
    for (float value : lit)
      s += std::pow(static_cast<double>(value), k);
    return s / texels;
  };
  double lo = 1.0, hi = 2.0;
  while (caustic_peak * mean_at(hi) > 1.0) {
    lo = hi;
    hi *= 2.0;
  }
  for (int step = 0; step < 30; ++step) {
    const double mid = 0.5 * (lo + hi);
    (caustic_peak * mean_at(mid) > 1.0 ? lo : hi) = mid;
  }
  sum = 0;
  for (int y = 0; y < kTextureStride; ++y) {
    for (int x = 0; x < kTextureStride; ++x) {
      float& value = tile[static_cast<std::size_t>(y) * kTextureStride + x];
      value = static_cast<float>(std::pow(static_cast<double>(value), hi));
      if (x < n && y < n) sum += value;
    }
  }
  mean = static_cast<float>(sum / texels);
  return tile;
}

// round(16 * N(0, 1)) by Box-Muller over our own uniform generator (std::normal_distribution is
// implementation-defined).
std::vector<std::int8_t> make_noise_table(std::uint64_t seed) {
  Rng rng(seed ^ 0x6e6f697365746162ULL);
  std::vector<std::int8_t> table(kNoiseTableSize);
  auto quantise = [](double z) {
    return static_cast<std::int8_t>(std::clamp(std::lround(z * kNoiseTableScale), -127L, 127L));
  };
  for (std::size_t i = 0; i + 1 < table.size(); i += 2) {
    const double r = std::sqrt(-2.0 * std::log(rng.uniform()));
    const double phi = 2.0 * kPi * rng.uniform();
    table[i] = quantise(r * std::cos(phi));
    table[i + 1] = quantise(r * std::sin(phi));
  }
  return table;
}

}  // namespace laserline::hal::sim
