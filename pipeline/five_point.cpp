// The five-point relative orientation solver (Nister): the essential matrices of five
// correspondences, from the ten cubic constraints on the null space of the epipolar constraints,
// by the real roots of a polynomial of degree ten in one unknown (isolated by its Sturm sequence,
// where an eigen decomposition of a 10x10 action matrix finds all roots, complex ones too, at
// about twice the cost). No allocation.
#include "pipeline/five_point.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

#include "pipeline/motion_internal.hpp"

namespace laserline::pipeline {

using namespace motion_detail;

namespace {

using Matrix10 = Eigen::Matrix<double, 10, 10>;

// Polynomials in x, y, z of degree <= 3, coefficients by monomial, in order of degree: 1; x y z;
// x2 xy xz y2 yz z2; x3 x2y x2z xy2 xyz xz2 y3 y2z yz2 z3. A polynomial of degree <= d uses the
// first 1, 4, 10 or 20 coefficients.
using Polynomial = std::array<double, 20>;
constexpr std::array<std::array<int, 3>, 20> kMonomials{
    {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {2, 0, 0}, {1, 1, 0}, {1, 0, 1},
     {0, 2, 0}, {0, 1, 1}, {0, 0, 2}, {3, 0, 0}, {2, 1, 0}, {2, 0, 1}, {1, 2, 0},
     {1, 1, 1}, {1, 0, 2}, {0, 3, 0}, {0, 2, 1}, {0, 1, 2}, {0, 0, 3}}};

// kProduct[i][j]: the monomial i * j (for the degrees multiplied here it is always <= 3).
constexpr std::array<std::array<int, 10>, 10> kProduct = [] {
  std::array<std::array<int, 10>, 10> table{};
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j) {
      table[i][j] = -1;
      for (int k = 0; k < 20; ++k) {
        if (kMonomials[k][0] == kMonomials[i][0] + kMonomials[j][0] &&
            kMonomials[k][1] == kMonomials[i][1] + kMonomials[j][1] &&
            kMonomials[k][2] == kMonomials[i][2] + kMonomials[j][2]) {
          table[i][j] = k;
        }
      }
    }
  }
  return table;
}();

// out += sign * a * b, a using its first na coefficients, b its first nb (4: linear, 10:
// quadratic). The sizes are constants, so that the loops unroll to fixed indices.
template <int na, int nb>
void multiply_add(const Polynomial& a, const Polynomial& b, double sign, Polynomial& out) {
  for (int i = 0; i < na; ++i) {
    const double scaled = sign * a[i];
    for (int j = 0; j < nb; ++j)
      out[kProduct[i][j]] += scaled * b[j];
  }
}

// Ten equations left * u + right * w = 0, as rows [left | right]: u = -reduced * w, by
// Gauss-Jordan elimination with full pivoting (as Eigen's FullPivLU, at a fraction of its cost
// for this size). False when left is singular to working precision.
using Elimination = std::array<std::array<double, 20>, 10>;
bool gauss_jordan(Elimination& a, Matrix10& reduced) {
  std::array<int, 10> unknown;  // the unknown of u column k of left stands for
  for (int k = 0; k < 10; ++k)
    unknown[k] = k;
  double largest_pivot = 0;
  for (int k = 0; k < 10; ++k) {
    int pivot_row = k, pivot_column = k;
    double pivot = -1;
    for (int row = k; row < 10; ++row) {
      for (int column = k; column < 10; ++column) {
        if (std::abs(a[row][column]) > pivot) {
          pivot = std::abs(a[row][column]);
          pivot_row = row;
          pivot_column = column;
        }
      }
    }
    if (k == 0) largest_pivot = pivot;
    if (!(pivot > 10 * std::numeric_limits<double>::epsilon() * largest_pivot)) return false;
    std::swap(a[k], a[pivot_row]);
    if (pivot_column != k) {
      for (auto& row : a)
        std::swap(row[k], row[pivot_column]);
      std::swap(unknown[k], unknown[pivot_column]);
    }
    const double inverse = 1 / a[k][k];
    for (int column = k; column < 20; ++column)
      a[k][column] *= inverse;
    for (int row = 0; row < 10; ++row) {
      const double factor = a[row][k];
      if (row == k || factor == 0) continue;
      for (int column = k; column < 20; ++column)
        a[row][column] -= factor * a[k][column];
    }
  }
  for (int k = 0; k < 10; ++k)
    for (int column = 0; column < 10; ++column)
      reduced(unknown[k], column) = a[k][10 + column];
  return reduced.allFinite();
}

// A Gauss-Newton step on the ten cubic constraints themselves at (x, y, z), kept where it
// lowers their residual: the steps through the resultant lose accuracy where two roots lie close
// together.
void polish(const std::array<Polynomial, 10>& equations, Eigen::Vector3d& solution) {
  // Column k: the monomials at (x, y, z) and their derivatives by x, y and z.
  const auto monomials = [](const Eigen::Vector3d& at, Eigen::Matrix<double, 20, 4>& out) {
    std::array<std::array<double, 4>, 3> power;
    for (int axis = 0; axis < 3; ++axis) {
      power[axis][0] = 1;
      for (int e = 1; e < 4; ++e)
        power[axis][e] = power[axis][e - 1] * at(axis);
    }
    for (int k = 0; k < 20; ++k) {
      const auto& exponent = kMonomials[k];
      out(k, 0) = power[0][exponent[0]] * power[1][exponent[1]] * power[2][exponent[2]];
      for (int axis = 0; axis < 3; ++axis) {
        double product = exponent[axis];
        for (int other = 0; other < 3; ++other)
          product *= power[other][std::max(0, exponent[other] - (other == axis ? 1 : 0))];
        out(k, 1 + axis) = product;
      }
    }
  };
  // Column i: the coefficients of equation i.
  static_assert(sizeof(equations) == 10 * 20 * sizeof(double));
  const Eigen::Map<const Eigen::Matrix<double, 20, 10>> coefficients(equations[0].data());
  Eigen::Matrix<double, 20, 4> at;
  monomials(solution, at);
  // Residuals (column 0) and their Jacobian.
  const Eigen::Matrix<double, 10, 4> evaluated = coefficients.transpose() * at;
  const auto r = evaluated.col(0);
  const auto jacobian = evaluated.rightCols<3>();
  const Eigen::Vector3d step =
      (jacobian.transpose() * jacobian).ldlt().solve(-jacobian.transpose() * r);
  if (!step.allFinite()) return;
  const Eigen::Vector3d moved = solution + step;
  monomials(moved, at);
  const Eigen::Matrix<double, 10, 1> moved_r = coefficients.transpose() * at.col(0);
  if (moved_r.squaredNorm() < r.squaredNorm()) solution = moved;
}

// Polynomials in one variable, coefficients from the constant term up, degree <= 10.
using Univariate = std::array<double, 11>;

double evaluate(const Univariate& p, int degree, double t) {
  double value = p[degree];
  for (int i = degree - 1; i >= 0; --i)
    value = value * t + p[i];
  return value;
}

// out += sign * a * b.
void multiply_add(const Univariate& a, int na, const Univariate& b, int nb, double sign,
                  Univariate& out) {
  for (int i = 0; i <= na; ++i)
    for (int j = 0; j <= nb; ++j)
      out[i + j] += sign * a[i] * b[j];
}

// The Sturm sequence of a polynomial of degree n: p, p', then the negated remainders, each one
// degree lower in the generic case; where a remainder vanishes the sequence ends early.
struct SturmSequence {
  std::array<Univariate, 11> polynomials{};
  int length = 0;
  int degree = 0;

  // Sign changes along the sequence at t (zeros skipped).
  int sign_changes(double t) const {
    int changes = 0;
    double last = 0;
    for (int k = 0; k < length; ++k) {
      const double value = evaluate(polynomials[k], degree - k, t);
      if (value == 0) continue;
      if (last != 0 && (value > 0) != (last > 0)) ++changes;
      last = value;
    }
    return changes;
  }
};

// Root of p in [lo, hi], where p changes sign once: Newton steps while they stay inside the
// bracket and at least halve the step before, bisection otherwise (rtsafe, Numerical Recipes).
double bracketed_root(const Univariate& p, const Univariate& derivative, int degree, double lo,
                      double hi) {
  const bool rising = evaluate(p, degree, hi) > 0;
  double t = 0.5 * (lo + hi);
  double step_before = hi - lo, step = step_before;
  for (int iteration = 0; iteration < 200; ++iteration) {
    const double value = evaluate(p, degree, t);
    if (value == 0) return t;
    if ((value > 0) == rising) {
      hi = t;
    } else {
      lo = t;
    }
    const double slope = evaluate(derivative, degree - 1, t);
    const double newton = slope != 0 ? t - value / slope : lo;
    const double step_before_last = step_before;
    step_before = step;
    if (newton > lo && newton < hi && 2 * std::abs(newton - t) <= std::abs(step_before_last)) {
      step = newton - t;
      t = newton;
    } else {
      step = 0.5 * (hi - lo);
      t = lo + step;
    }
    if (std::abs(step) <= 1e-15 * (1 + std::abs(t))) return t;
  }
  return t;
}

// The distinct real roots of p (degree <= 10), isolated by its Sturm sequence; returns how many.
int real_roots(Univariate p, int degree, std::array<double, 10>& roots) {
  double largest = 0;
  for (int i = 0; i <= degree; ++i)
    largest = std::max(largest, std::abs(p[i]));
  if (!(largest > 0) || !std::isfinite(largest)) return 0;
  // A vanishing leading coefficient is a root at infinity: no essential matrix.
  while (degree > 0 && !(std::abs(p[degree]) > 1e-14 * largest))
    --degree;
  if (degree == 0) return 0;
  for (int i = 0; i < degree; ++i)
    p[i] /= p[degree];
  p[degree] = 1;

  SturmSequence sturm;
  sturm.degree = degree;
  sturm.polynomials[0] = p;
  Univariate& derivative = sturm.polynomials[1];
  for (int i = 1; i <= degree; ++i)
    derivative[i - 1] = i * p[i] / degree;
  sturm.length = 2;
  for (int k = 2; k <= degree; ++k) {
    // s_k = -(s_{k-2} mod s_{k-1}); s_{k-2} has degree m + 1 = degree - k + 2.
    const Univariate& above = sturm.polynomials[k - 2];
    const Univariate& divisor = sturm.polynomials[k - 1];
    const int m = degree - k + 1;
    const double lead = divisor[m];
    if (!(std::abs(lead) > 1e-14 * std::abs(above[m + 1]))) break;
    const double a = above[m + 1] / lead;
    const double b = (above[m] - a * divisor[m - 1]) / lead;
    Univariate& remainder = sturm.polynomials[k];
    remainder.fill(0);
    // above - (a t + b) divisor, whose terms of degree m + 1 and m vanish; negated.
    for (int i = 0; i < m; ++i) {
      double value = above[i] - b * divisor[i];
      if (i > 0) value -= a * divisor[i - 1];
      remainder[i] = -value;
    }
    // Scaled by a positive factor (sign changes unaffected) to keep the magnitudes in range.
    double scale = 0;
    for (int i = 0; i < m; ++i)
      scale = std::max(scale, std::abs(remainder[i]));
    if (!(scale > 0)) break;
    for (int i = 0; i < m; ++i)
      remainder[i] /= scale;
    sturm.length = k + 1;
  }

  // Fujiwara's bound on the roots' magnitude.
  double bound = 0;
  for (int i = 1; i <= degree; ++i)
    bound = std::max(bound, std::pow(std::abs(p[degree - i]), 1.0 / i));
  bound = 2 * bound + 1e-12;
  Univariate slope{};
  for (int i = 1; i <= degree; ++i)
    slope[i - 1] = i * p[i];

  struct Interval {
    double lo, hi;
    int changes_lo, changes_hi, depth;
  };
  std::array<Interval, 64> stack;
  int top = 0;
  stack[top++] = {-bound, bound, sturm.sign_changes(-bound), sturm.sign_changes(bound), 0};
  int count = 0;
  while (top > 0 && count < 10) {
    const Interval interval = stack[--top];
    const int inside = interval.changes_lo - interval.changes_hi;
    if (inside <= 0) continue;
    const double p_lo = evaluate(p, degree, interval.lo), p_hi = evaluate(p, degree, interval.hi);
    if (inside == 1 && (p_lo > 0) != (p_hi > 0)) {
      roots[count++] = bracketed_root(p, slope, degree, interval.lo, interval.hi);
      continue;
    }
    const double middle = 0.5 * (interval.lo + interval.hi);
    // Roots closer than the bisection resolves: one of them stands for all.
    if (interval.depth >= 100 || !(middle > interval.lo && middle < interval.hi) ||
        top + 2 > static_cast<int>(stack.size())) {
      roots[count++] = middle;
      continue;
    }
    const int changes_middle = sturm.sign_changes(middle);
    stack[top++] = {interval.lo, middle, interval.changes_lo, changes_middle, interval.depth + 1};
    stack[top++] = {middle, interval.hi, changes_middle, interval.changes_hi, interval.depth + 1};
  }
  return count;
}

}  // namespace

int five_point_essentials(const std::array<std::array<double, 2>, 5>& previous,
                          const std::array<std::array<double, 2>, 5>& current,
                          std::array<std::array<double, 9>, 10>& essentials) {
  // E = x X + y Y + z Z + W over the null space of the five epipolar constraints.
  Eigen::Matrix<double, 9, 5> constraints;
  for (int k = 0; k < 5; ++k) {
    constraints.col(k) = epipolar_row(previous[k][0], previous[k][1], current[k][0], current[k][1]);
  }
  const Eigen::HouseholderQR<Eigen::Matrix<double, 9, 5>> qr(constraints);
  const Eigen::Matrix<double, 9, 9> q = qr.householderQ();
  // Rank below five: the sample does not fix a four-dimensional null space.
  const auto& r = qr.matrixQR();
  double largest = 0;
  for (int k = 0; k < 5; ++k)
    largest = std::max(largest, std::abs(r(k, k)));
  for (int k = 0; k < 5; ++k)
    if (!(std::abs(r(k, k)) > 1e-10 * largest)) return 0;

  // Entries of E as linear polynomials: coefficients of 1, x, y, z.
  std::array<std::array<Polynomial, 3>, 3> e{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Polynomial& p = e[i][j];
      p.fill(0);
      p[0] = q(3 * i + j, 8);
      p[1] = q(3 * i + j, 5);
      p[2] = q(3 * i + j, 6);
      p[3] = q(3 * i + j, 7);
    }
  }
  // Ten cubic constraints: det(E) = 0 and 2 E E^T E - trace(E E^T) E = 0.
  std::array<Polynomial, 10> equations{};
  for (Polynomial& p : equations)
    p.fill(0);
  {
    Polynomial minor{};
    const auto cofactor = [&](int r1, int c1, int r2, int c2) {
      minor.fill(0);
      multiply_add<4, 4>(e[r1][c1], e[r2][c2], 1, minor);
      multiply_add<4, 4>(e[r1][c2], e[r2][c1], -1, minor);
    };
    cofactor(1, 1, 2, 2);
    multiply_add<10, 4>(minor, e[0][0], 1, equations[0]);
    cofactor(1, 0, 2, 2);
    multiply_add<10, 4>(minor, e[0][1], -1, equations[0]);
    cofactor(1, 0, 2, 1);
    multiply_add<10, 4>(minor, e[0][2], 1, equations[0]);
  }
  std::array<std::array<Polynomial, 3>, 3> eet{};
  Polynomial trace{};
  trace.fill(0);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (j < i) {  // E E^T is symmetric
        eet[i][j] = eet[j][i];
        continue;
      }
      eet[i][j].fill(0);
      for (int k = 0; k < 3; ++k)
        multiply_add<4, 4>(e[i][k], e[j][k], 1, eet[i][j]);
    }
    for (int k = 0; k < 10; ++k)
      trace[k] += eet[i][i][k];
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Polynomial& p = equations[1 + 3 * i + j];
      for (int k = 0; k < 3; ++k)
        multiply_add<10, 4>(eet[i][k], e[k][j], 2, p);
      multiply_add<10, 4>(trace, e[i][j], -1, p);
    }
  }

  // Gauss-Jordan (Nister's hidden variable z): ten monomials in terms of the ten others,
  // (xz2 xz x yz2 yz y z3 z2 z 1), which are (x, y, 1) times polynomials in z.
  constexpr std::array<int, 10> kEliminated{12, 4, 17, 7, 14, 5, 10, 16, 11, 13};
  constexpr std::array<int, 10> kRemaining{15, 6, 1, 18, 8, 2, 19, 9, 3, 0};
  Elimination system;
  for (int row = 0; row < 10; ++row) {
    for (int k = 0; k < 10; ++k) {
      system[row][k] = equations[row][kEliminated[k]];
      system[row][10 + k] = equations[row][kRemaining[k]];
    }
  }
  Matrix10 reduced;  // eliminated monomial i = -reduced.row(i) . remaining
  if (!gauss_jordan(system, reduced)) return 0;
  // x2z - z x2, y2z - z y2, xyz - z xy vanish: B(z) (x, y, 1)^T = 0 with B's entries of degree
  // 3, 3 and 4 in z, so det B(z) = 0 is of degree 10.
  std::array<std::array<Univariate, 3>, 3> b{};
  std::array<std::array<int, 3>, 3> degree{};
  for (int row = 0; row < 3; ++row) {
    const auto with_z = reduced.row(2 * row), without_z = reduced.row(2 * row + 1);
    for (int variable = 0; variable < 2; ++variable) {
      const int o = 3 * variable;
      b[row][variable] = {-with_z(o + 2), without_z(o + 2) - with_z(o + 1),
                          without_z(o + 1) - with_z(o), without_z(o)};
      degree[row][variable] = 3;
    }
    b[row][2] = {-with_z(9), without_z(9) - with_z(8), without_z(8) - with_z(7),
                 without_z(7) - with_z(6), without_z(6)};
    degree[row][2] = 4;
  }
  Univariate determinant{};
  const std::array<std::array<int, 3>, 3> kTerms{{{0, 1, 2}, {1, 2, 0}, {2, 0, 1}}};
  for (const auto& [c0, c1, c2] : kTerms) {
    // b0c0 (b1c1 b2c2 - b1c2 b2c1), summed over the cyclic permutations.
    Univariate minor{};
    multiply_add(b[1][c1], degree[1][c1], b[2][c2], degree[2][c2], 1, minor);
    multiply_add(b[1][c2], degree[1][c2], b[2][c1], degree[2][c1], -1, minor);
    const int minor_degree = degree[1][c1] + degree[2][c2];
    multiply_add(b[0][c0], degree[0][c0], minor, minor_degree, 1, determinant);
  }
  std::array<double, 10> roots;
  const int root_count = real_roots(determinant, 10, roots);
  int count = 0;
  for (int k = 0; k < root_count; ++k) {
    // Polished on det B(z) itself, evaluated from B's entries: the expanded polynomial's
    // coefficients carry rounding errors the root is sensitive to.
    double z = roots[k];
    for (int polish = 0; polish < 2; ++polish) {
      Eigen::Matrix3d value, slope;
      for (int row = 0; row < 3; ++row) {
        for (int column = 0; column < 3; ++column) {
          const Univariate& entry = b[row][column];
          const int d = degree[row][column];
          double v = entry[d], s = 0;
          for (int i = d - 1; i >= 0; --i) {
            s = s * z + v;
            v = v * z + entry[i];
          }
          value(row, column) = v;
          slope(row, column) = s;
        }
      }
      // Jacobi's formula: d det B = trace(adj(B) dB).
      Eigen::Matrix3d adjugate;
      adjugate.col(0) = value.row(1).cross(value.row(2));
      adjugate.col(1) = value.row(2).cross(value.row(0));
      adjugate.col(2) = value.row(0).cross(value.row(1));
      const double derivative = (adjugate * slope).trace();
      const double step = value.determinant() / derivative;
      if (!std::isfinite(step) || std::abs(step) > 1e-6 * (1 + std::abs(z))) break;
      z -= step;
    }
    // (x, y, 1) spans the null space of B(z): the cross product of its two rows that give the
    // largest.
    Eigen::Matrix3d at_z;
    for (int row = 0; row < 3; ++row)
      for (int column = 0; column < 3; ++column)
        at_z(row, column) = evaluate(b[row][column], degree[row][column], z);
    Eigen::Vector3d null = at_z.row(0).cross(at_z.row(1));
    for (const auto& [r0, r1] : {std::array<int, 2>{0, 2}, std::array<int, 2>{1, 2}}) {
      const Eigen::Vector3d other = at_z.row(r0).cross(at_z.row(r1));
      if (other.squaredNorm() > null.squaredNorm()) null = other;
    }
    if (!(std::abs(null(2)) > 1e-14 * null.norm())) continue;
    Eigen::Vector3d solution(null(0) / null(2), null(1) / null(2), z);
    polish(equations, solution);
    const double x = solution(0), y = solution(1);
    z = solution(2);
    std::array<double, 9>& out = essentials[count];
    double norm = 0;
    for (int i = 0; i < 9; ++i) {
      out[i] = x * q(i, 5) + y * q(i, 6) + z * q(i, 7) + q(i, 8);
      norm += out[i] * out[i];
    }
    norm = std::sqrt(norm);
    if (!(norm > 0) || !std::isfinite(norm)) continue;
    for (double& value : out)
      value /= norm;
    ++count;
  }
  return count;
}

}  // namespace laserline::pipeline
