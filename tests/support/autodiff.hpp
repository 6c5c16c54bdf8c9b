// tests/support/autodiff.hpp — Eigen's forward-mode AutoDiffScalar as an independent check of
// analytic Jacobians: the same templated smg code is instantiated with AD scalars.
#pragma once

#include <Eigen/Core>
#include <unsupported/Eigen/AutoDiff>

namespace smg::test {

using AD = Eigen::AutoDiffScalar<Eigen::VectorXd>;

// x as AD scalars whose derivative vectors are unit vectors offset..offset+n-1 of `total`.
template <int N>
Eigen::Matrix<AD, N, 1> ad_variables(const Eigen::Matrix<double, N, 1>& x, Eigen::Index total,
                                     Eigen::Index offset = 0) {
  Eigen::Matrix<AD, N, 1> out;
  for (Eigen::Index k = 0; k < x.size(); ++k)
    out(k) = AD(x(k), total, offset + k);
  return out;
}

// Constant (zero-derivative) AD copy of x.
template <int N>
Eigen::Matrix<AD, N, 1> ad_constant(const Eigen::Matrix<double, N, 1>& x, Eigen::Index total) {
  Eigen::Matrix<AD, N, 1> out;
  for (Eigen::Index k = 0; k < x.size(); ++k) out(k) = AD(x(k), Eigen::VectorXd::Zero(total));
  return out;
}

// Rows = outputs, cols = derivatives.
template <int N>
Eigen::MatrixXd ad_jacobian(const Eigen::Matrix<AD, N, 1>& y, Eigen::Index total) {
  Eigen::MatrixXd J(y.size(), total);
  for (Eigen::Index r = 0; r < y.size(); ++r) {
    if (y(r).derivatives().size() == total)
      J.row(r) = y(r).derivatives().transpose();
    else
      J.row(r).setZero();  // a constant result carries an empty derivative vector
  }
  return J;
}

template <int N>
Eigen::Matrix<double, N, 1> ad_values(const Eigen::Matrix<AD, N, 1>& y) {
  Eigen::Matrix<double, N, 1> out;
  for (Eigen::Index k = 0; k < y.size(); ++k) out(k) = y(k).value();
  return out;
}

}  // namespace smg::test
