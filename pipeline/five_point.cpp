// The five-point relative orientation solver (Nister; Stewenius' Groebner basis form): the
// essential matrices of five correspondences, from the ten cubic constraints on the null space of
// the epipolar constraints, by the eigenvalues of the action matrix. No allocation.
#include "pipeline/five_point.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <complex>

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

// out += sign * a * b, a using its first na coefficients, b its first 4 (linear) or 10.
void multiply_add(const Polynomial& a, int na, const Polynomial& b, int nb, double sign,
                  Polynomial& out) {
  for (int i = 0; i < na; ++i) {
    if (a[i] == 0) continue;
    for (int j = 0; j < nb; ++j)
      out[kProduct[i][j]] += sign * a[i] * b[j];
  }
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
      multiply_add(e[r1][c1], 4, e[r2][c2], 4, 1, minor);
      multiply_add(e[r1][c2], 4, e[r2][c1], 4, -1, minor);
    };
    cofactor(1, 1, 2, 2);
    multiply_add(minor, 10, e[0][0], 4, 1, equations[0]);
    cofactor(1, 0, 2, 2);
    multiply_add(minor, 10, e[0][1], 4, -1, equations[0]);
    cofactor(1, 0, 2, 1);
    multiply_add(minor, 10, e[0][2], 4, 1, equations[0]);
  }
  std::array<std::array<Polynomial, 3>, 3> eet{};
  Polynomial trace{};
  trace.fill(0);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      eet[i][j].fill(0);
      for (int k = 0; k < 3; ++k)
        multiply_add(e[i][k], 4, e[j][k], 4, 1, eet[i][j]);
    }
    for (int k = 0; k < 10; ++k)
      trace[k] += eet[i][i][k];
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Polynomial& p = equations[1 + 3 * i + j];
      for (int k = 0; k < 3; ++k)
        multiply_add(eet[i][k], 10, e[k][j], 4, 2, p);
      multiply_add(trace, 10, e[i][j], 4, -1, p);
    }
  }

  // Gauss-Jordan: the ten cubic monomials in terms of the ten monomials of degree <= 2, the
  // basis b = (x2 xy xz y2 yz z2 x y z 1) of the quotient ring.
  constexpr std::array<int, 10> kBasis{4, 5, 6, 7, 8, 9, 1, 2, 3, 0};
  Matrix10 cubic, rest;
  for (int row = 0; row < 10; ++row) {
    for (int k = 0; k < 10; ++k) {
      cubic(row, k) = equations[row][10 + k];
      rest(row, k) = equations[row][kBasis[k]];
    }
  }
  const Eigen::FullPivLU<Matrix10> lu(cubic);
  if (!lu.isInvertible()) return 0;
  const Matrix10 reduced = lu.solve(rest);  // cubic monomials = -reduced * b
  // Multiplication by x on the basis: x b = action * b; the eigenvectors at the solutions are b.
  Matrix10 action = Matrix10::Zero();
  for (int k = 0; k < 6; ++k)  // x * (x2 xy xz y2 yz z2) = x3 x2y x2z xy2 xyz xz2
    action.row(k) = -reduced.row(k);
  action(6, 0) = 1;  // x * x = x2
  action(7, 1) = 1;  // x * y = xy
  action(8, 2) = 1;  // x * z = xz
  action(9, 6) = 1;  // x * 1 = x
  if (!action.allFinite()) return 0;
  // Eigenvalues only (the Schur vectors cost as much again); the eigenvector of a real one
  // from (action - x I) b = 0 with b's last entry 1, in the least-squares sense.
  const Eigen::EigenSolver<Matrix10> eigen(action, false);
  if (eigen.info() != Eigen::Success) return 0;
  int count = 0;
  for (int k = 0; k < 10; ++k) {
    const std::complex<double> lambda = eigen.eigenvalues()(k);
    if (std::abs(lambda.imag()) > 1e-8 * (1 + std::abs(lambda.real()))) continue;
    Eigen::Matrix<double, 10, 9> shifted = action.leftCols<9>();
    for (int i = 0; i < 9; ++i)
      shifted(i, i) -= lambda.real();
    Eigen::Matrix<double, 10, 1> right = -action.col(9);
    right(9) += lambda.real();
    const Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 10, 9>> solver(shifted);
    if (solver.rank() < 9) continue;
    const Eigen::Matrix<double, 9, 1> b = solver.solve(right);
    const double x = b(6), y = b(7), z = b(8);
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
