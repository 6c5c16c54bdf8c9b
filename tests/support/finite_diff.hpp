// tests/support/finite_diff.hpp — central finite differences and error measures used to check
// every analytic Jacobian in smg.
//
// Inputs and outputs are flat Eigen vectors; manifold-valued inputs (rotations) are perturbed
// through a user lambda (e.g. q ⊗ Exp(h e_k) for the right tangent), so the same routine checks
// raw and tangent Jacobians alike. Central differences have truncation error O(h^2 f''') and
// rounding error O(eps/h); h = 1e-6 (relative to the input scale) keeps both near 1e-10 in
// double for the smooth functions tested here.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "smg/core/so3.hpp"

namespace smg::test {

// J(:, k) = (f(x + h e_k) - f(x - h e_k)) / (2h).
inline Eigen::MatrixXd central_jacobian(
    const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f, const Eigen::VectorXd& x,
    double h = 1e-6) {
  const Eigen::VectorXd f0 = f(x);
  Eigen::MatrixXd J(f0.size(), x.size());
  for (Eigen::Index k = 0; k < x.size(); ++k) {
    Eigen::VectorXd xp = x, xm = x;
    xp(k) += h;
    xm(k) -= h;
    J.col(k) = (f(xp) - f(xm)) / (2 * h);
  }
  return J;
}

// Jacobian w.r.t. a perturbation d in R^n applied by `apply(d)` (which returns f evaluated at
// the perturbed input): J(:, k) = (apply(h e_k) - apply(-h e_k)) / (2h).
inline Eigen::MatrixXd central_jacobian_perturbed(
    const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& apply, Eigen::Index n,
    double h = 1e-6) {
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  return central_jacobian(apply, zero, h);
}

// ‖A − B‖_F / max(‖B‖_F, floor): the relative error of an analytic Jacobian A against a
// reference B. `floor` keeps an all-zero reference from turning rounding noise into 100%.
template <class DA, class DB>
double relative_error(const Eigen::MatrixBase<DA>& A, const Eigen::MatrixBase<DB>& B,
                      double floor = 1e-12) {
  return (A.template cast<double>() - B.template cast<double>()).norm() /
         std::max(B.template cast<double>().norm(), floor);
}

// ‖a − b‖₂ / max(‖b‖₂, floor) over two equally long sequences (std::vector of double or float):
// the relative error of an analytic gradient a against a reference b.
template <class A, class B>
double relative_error(const std::vector<A>& a, const std::vector<B>& b, double floor = 1e-300) {
  double num = 0, den = 0;
  for (std::size_t k = 0; k < b.size(); ++k) {
    const double d = static_cast<double>(a[k]) - static_cast<double>(b[k]);
    num += d * d;
    den += static_cast<double>(b[k]) * static_cast<double>(b[k]);
  }
  return std::sqrt(num) / std::max(std::sqrt(den), floor);
}

// One central difference of a scalar function f() in one scalar input p, changed in place:
// (f() at p0 + h − f() at p0 − h) / (2h); p is p0 again afterwards.
template <class F>
double central_difference(double& p, F&& f, double h = 1e-6) {
  const double p0 = p;
  p = p0 + h;
  const double fp = f();
  p = p0 - h;
  const double fm = f();
  p = p0;
  return (fp - fm) / (2 * h);
}

// Central differences of f() in every entry of a flat parameter array x (changed in place and
// restored): the finite-difference gradient.
template <class F>
std::vector<double> central_gradient(std::vector<double>& x, F&& f, double h = 1e-6) {
  std::vector<double> g(x.size());
  for (std::size_t k = 0; k < x.size(); ++k) g[k] = central_difference(x[k], f, h);
  return g;
}

// One central difference of f() along the right tangent e_c of a rotation q0, applied by
// set(q): (f() at q0 ⊗ Exp(h e_c) − f() at q0 ⊗ Exp(−h e_c)) / (2h); set(q0) afterwards.
template <class Set, class F>
double central_difference_tangent(const Eigen::Quaterniond& q0, int c, Set&& set, F&& f,
                                  double h = 1e-6) {
  const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(c);
  set(Eigen::Quaterniond(q0 * smg::so3::exp(e)));
  const double fp = f();
  set(Eigen::Quaterniond(q0 * smg::so3::exp(Eigen::Vector3d(-e))));
  const double fm = f();
  set(q0);
  return (fp - fm) / (2 * h);
}

}  // namespace smg::test
