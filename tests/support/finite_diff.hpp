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
#include <functional>

#include <Eigen/Core>

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

}  // namespace smg::test
