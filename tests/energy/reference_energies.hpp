// tests/energy/reference_energies.hpp — straightforward implementations of docs/design.md's
// "Confidence", "C-ARAP" and "LRM" equations, term by term with Eigen fixed-size types, written
// independently of the library's kernels. They serve as the value reference of the tests and,
// instantiated with Eigen::AutoDiffScalar, as the per-term automatic-differentiation baseline
// (tests and bench/bench_energy.cpp).
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Dense>
#include <unsupported/Eigen/AutoDiff>

#include "smg/energy/options.hpp"
#include "energy/scene.hpp"

namespace smg::test::ref {

// Value with the derivatives dropped (ω held constant): identity for plain scalars.
inline double constant(double v) { return v; }
inline float constant(float v) { return v; }
template <class D>
Eigen::AutoDiffScalar<D> constant(const Eigen::AutoDiffScalar<D>& v) {
  Eigen::AutoDiffScalar<D> out(v.value());
  out.derivatives() = D::Zero(v.derivatives().size());
  return out;
}

template <class S>
Vector3<S> velocity(const std::vector<Vector3<S>>& X, Index T, Index N, Index t, Index i) {
  if (T < 2) return Vector3<S>::Zero();
  if (t < T - 1) return Vector3<S>(X[(t + 1) * N + i] - X[t * N + i]);
  return Vector3<S>(X[(T - 1) * N + i] - X[(T - 2) * N + i]);
}

template <class S>
std::vector<Vector3<S>> positions_of(const Scene<double>& s) {
  std::vector<Vector3<S>> X(static_cast<std::size_t>(s.T * s.N));
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i) X[t * s.N + i] = s.pos(t, i).cast<S>();
  return X;
}
template <class S>
std::vector<Matrix3<S>> rotations_of(const Scene<double>& s) {
  std::vector<Matrix3<S>> R(static_cast<std::size_t>(s.T * s.N));
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i)
      R[t * s.N + i] = s.rot(t, i).normalized().toRotationMatrix().cast<S>();
  return R;
}

// ---- Confidence (E2)-(E6), with row-normalised topology weights. ----
// Computed in R (long double gives a reference whose own rounding is far below double's: the
// differences of edge lengths in (E4) cancel), returned in double.
template <class R = double>
void confidence(const Scene<double>& s, const ConfidenceOptions& o, bool use_visibility,
                std::vector<double>& c, std::vector<double>& cm, std::vector<double>& cr) {
  const Index T = s.T, N = s.N, K = s.K;
  const auto X = positions_of<R>(s);
  std::vector<R> e(static_cast<std::size_t>(T * N), R(0));
  auto length = [&](Index t, Index i, Index j) { return (X[t * N + j] - X[t * N + i]).norm(); };
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i) {
      R W = 0, acc = 0;
      for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) {
        const Index j = s.idx[i * K + k];
        R change = 0;
        if (T >= 2) {
          const Index a = t < T - 1 ? t + 1 : T - 1, b = t < T - 1 ? t : T - 2;
          change = std::abs(length(a, i, j) - length(b, i, j));
        }
        acc += R(s.w[i * K + k]) * change;
        W += R(s.w[i * K + k]);
      }
      e[t * N + i] = W > 0 ? acc / W : R(0);
    }
  c.assign(static_cast<std::size_t>(T * N), 0.0);
  cm = c;
  cr = c;
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i) {
      R W = 0;
      for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) W += R(s.w[i * K + k]);
      Vector3<R> vbar = Vector3<R>::Zero();
      R ebar = 0, sv = 0, sl = 0;
      if (W > 0) {
        for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) {
          const Index j = s.idx[i * K + k];
          vbar += R(s.w[i * K + k]) / W * velocity(X, T, N, t, j);
          ebar += R(s.w[i * K + k]) / W * e[t * N + j];
        }
        for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) {
          const Index j = s.idx[i * K + k];
          sv += R(s.w[i * K + k]) / W * (velocity(X, T, N, t, j) - vbar).norm();
          sl += R(s.w[i * K + k]) / W * std::abs(e[t * N + j] - ebar);
        }
      }
      const R rv = (velocity(X, T, N, t, i) - vbar).norm();
      const R rl = std::abs(e[t * N + i] - ebar);
      const R m = std::exp(-std::pow(rv / (R(o.kappa_m) * (sv + R(o.eps))), 2));
      const R r = std::exp(-std::pow(rl / (R(o.kappa_r) * (sl + R(o.eps))), 2));
      cm[t * N + i] = double(m);
      cr[t * N + i] = double(r);
      const R vis = use_visibility ? R(s.v[t * N + i]) : R(1);
      c[t * N + i] = double(vis * std::pow(m, R(o.lambda_m)) * std::pow(r, R(o.lambda_r)));
    }
}

// ---- C-ARAP (E7)-(E9) ----
// One term: weight * [λc ‖d_s − d_t‖² + λl (‖d_s‖ − ‖d_t‖)²] with d = Rᵀ (x_j − x_i).
template <class S>
S carap_pair(const Vector3<S>& xi_t, const Vector3<S>& xj_t, const Matrix3<S>& Ri_t,
             const Vector3<S>& xi_s, const Vector3<S>& xj_s, const Matrix3<S>& Ri_s, double weight,
             double lambda_c, double lambda_l) {
  using std::sqrt;
  const Vector3<S> dt = Ri_t.transpose() * (xj_t - xi_t);
  const Vector3<S> ds = Ri_s.transpose() * (xj_s - xi_s);
  const S len = sqrt(ds.squaredNorm()) - sqrt(dt.squaredNorm());
  return weight * (lambda_c * (ds - dt).squaredNorm() + lambda_l * len * len);
}

// conf: nullptr = all 1 (plain ARAP with alpha = 1).
template <class S>
S carap(const Scene<double>& s, const std::vector<Vector3<S>>& X, const std::vector<Matrix3<S>>& R,
        const std::vector<double>* conf, const CarapOptions& o) {
  const Index T = s.T, N = s.N, K = s.K;
  S total(0);
  Index terms = 0;
  for (const Gap& g : o.gaps) terms += std::max<Index>(0, T - g.delta);
  Index edges = 0;
  for (Index i = 0; i < N; ++i)
    for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) ++edges;
  terms *= edges;
  for (const Gap& g : o.gaps)
    for (Index t = 0; t + g.delta < T; ++t)
      for (Index i = 0; i < N; ++i)
        for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) {
          const Index j = s.idx[i * K + k], u = t + g.delta;
          const double c = conf ? (*conf)[t * N + j] : 1.0;
          const double wt = g.weight * s.w[i * K + k] * (o.alpha + (1 - o.alpha) * c);
          total += carap_pair<S>(X[t * N + i], X[t * N + j], R[t * N + i], X[u * N + i],
                                 X[u * N + j], R[u * N + i], wt, o.lambda_c, o.lambda_l);
        }
  total *= o.weight;
  if (o.normalization == Normalization::mean) total /= double(std::max<Index>(terms, 1));
  return total;
}

// ---- LRM (E11)-(E14) ----
template <class S>
S huber(const S& r2, double delta) {
  using std::sqrt;
  if (r2 <= delta * delta) return 0.5 * r2;
  return delta * (sqrt(r2) - 0.5 * delta);
}

// One neighbourhood: positions x_k^t, velocities u_k^t and raw weights a_k = w_ik (α + (1−α)c).
template <class S>
S lrm_neighbourhood(const std::vector<Vector3<S>>& x, const std::vector<Vector3<S>>& u,
                    const std::vector<double>& a, double delta, double mu_factor, bool detach,
                    Vector3<S>* omega_out = nullptr) {
  const std::size_t n = x.size();
  double W = 0;
  for (double v : a) W += v;
  if (n == 0 || !(W > 0)) return S(0);
  Vector3<S> g = Vector3<S>::Zero(), vb = Vector3<S>::Zero();
  for (std::size_t k = 0; k < n; ++k) {
    g += (a[k] / W) * x[k];
    vb += (a[k] / W) * u[k];
  }
  Matrix3<S> A = Matrix3<S>::Zero();
  Vector3<S> b = Vector3<S>::Zero();
  for (std::size_t k = 0; k < n; ++k) {
    const Vector3<S> xt = x[k] - g, ut = u[k] - vb;
    A += (a[k] / W) * (xt.squaredNorm() * Matrix3<S>::Identity() - xt * xt.transpose());
    b += (a[k] / W) * xt.cross(ut);
  }
  const S tau = A.trace();
  Vector3<S> omega = Vector3<S>::Zero();
  if (tau > 0) {
    const Matrix3<S> M = A + (mu_factor * tau) * Matrix3<S>::Identity();
    omega = M.inverse() * b;
  }
  if (detach)
    for (int c = 0; c < 3; ++c) omega(c) = constant(omega(c));
  if (omega_out) *omega_out = omega;
  S total(0);
  for (std::size_t k = 0; k < n; ++k) {
    const Vector3<S> r = (u[k] - vb) - omega.cross(Vector3<S>(x[k] - g));
    total += (a[k] / W) * huber<S>(r.squaredNorm(), delta);
  }
  return total;
}

template <class S>
S lrm(const Scene<double>& s, const std::vector<Vector3<S>>& X, const std::vector<double>* conf,
      const LrmOptions& o, double mu_factor) {
  const Index T = s.T, N = s.N, K = s.K;
  S total(0);
  Index edges = 0;
  for (Index i = 0; i < N; ++i)
    for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) ++edges;
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i) {
      std::vector<Vector3<S>> x, u;
      std::vector<double> a;
      for (Index k = 0; k < K && s.idx[i * K + k] >= 0; ++k) {
        const Index j = s.idx[i * K + k];
        x.push_back(X[t * N + j]);
        u.push_back(velocity(X, T, N, t, j));
        const double c = conf ? (*conf)[t * N + j] : 1.0;
        a.push_back(s.w[i * K + k] * (o.alpha + (1 - o.alpha) * c));
      }
      total += lrm_neighbourhood<S>(x, u, a, o.huber_delta, mu_factor, o.detach_omega);
    }
  total *= o.weight;
  if (o.normalization == Normalization::mean) total /= double(std::max<Index>(T * edges, 1));
  return total;
}

}  // namespace smg::test::ref
