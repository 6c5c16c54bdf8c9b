// tests/skin/skin_test_support.hpp — shared helpers of the skin tests: random drivers, an
// independent reference blend built from core dual quaternions, finite-difference Jacobians
// of skin_point, and a small random scene for the batched functions.
#pragma once

#include <cstdint>
#include <vector>

#include "smg/core/dual_quaternion.hpp"
#include "smg/core/so3.hpp"
#include "smg/skin.hpp"
#include "support/finite_diff.hpp"
#include "support/random.hpp"

namespace smg::test {

using Drivers = std::vector<SkinDriver<double>>;

// D drivers with random poses (positions in [-scale, scale]^3) and distinct positive weights
// summing to 1 (distinct so that the pivot is stable under finite differences).
inline Drivers random_drivers(Rng& rng, int D, double scale = 2.0) {
  Drivers d(static_cast<std::size_t>(D));
  double sum = 0;
  for (int k = 0; k < D; ++k) {
    d[k].x_ref = rng.vec3(scale);
    d[k].q_ref = rng.quaternion();
    d[k].x_t = rng.vec3(scale);
    d[k].q_t = rng.quaternion();
    d[k].weight = 0.2 + 0.8 * (k + 1) / double(D) + 0.01 * rng.uniform(0, 1);
    sum += d[k].weight;
  }
  for (auto& x : d) x.weight /= sum;
  return d;
}

// Reference DQB from core: T_k = DQ(q_t, x_t) ⊗ DQ(q_ref, x_ref)^-1, signs aligned to the
// canonical pivot, weighted sum, core transform_point (which divides by |b_r|), q' = ĉ0 ⊗ q_p.
inline void reference_dqb(const Drivers& d, const Vector3<double>& p, const Quaternion<double>& qp,
                          Vector3<double>* p_out, Quaternion<double>* q_out) {
  std::size_t piv = 0;
  for (std::size_t k = 1; k < d.size(); ++k)
    if (d[k].weight > d[piv].weight) piv = k;
  std::vector<Vector8<double>> T;
  for (const auto& x : d) {
    const auto Tr = dual_quaternion_from_rotation_translation(x.q_ref, x.x_ref);
    const auto Tt = dual_quaternion_from_rotation_translation(x.q_t, x.x_t);
    T.push_back(dual_quaternion_product(Tt, dual_quaternion_conjugate(Tr)).coeffs_wxyz());
  }
  Vector4<double> rp = T[piv].head<4>();
  const Quaternion<double> rq = from_wxyz(rp);
  if (canonical(rq).coeffs() != rq.coeffs()) rp = -rp;
  Vector8<double> b = Vector8<double>::Zero();
  for (std::size_t k = 0; k < d.size(); ++k)
    b += d[k].weight * (T[k].head<4>().dot(rp) >= 0 ? 1.0 : -1.0) * T[k];
  const auto B = DualQuaternion<double>::from_coeffs_wxyz(b);
  *p_out = dual_quaternion_transform_point(B, p);
  *q_out = normalized(B.real) * qp;
}

// Reference LBS: Σ w_k (R_t R_ref^T (p − x_ref) + x_t) with rotation matrices.
inline Vector3<double> reference_lbs(const Drivers& d, const Vector3<double>& p) {
  Vector3<double> out = Vector3<double>::Zero();
  for (const auto& x : d) {
    const Matrix3<double> R = x.q_t.toRotationMatrix() * x.q_ref.toRotationMatrix().transpose();
    out += x.weight * (R * (p - x.x_ref) + x.x_t);
  }
  return out;
}

// The 6-vector (p', log(conj(q0) ⊗ q')) — the output in the right tangent at q0.
inline Eigen::VectorXd output_tangent(SkinMethod m, const Drivers& d, const Vector3<double>& p,
                                      const Quaternion<double>& qp, const Quaternion<double>& q0) {
  Vector3<double> po;
  Quaternion<double> qo;
  skin_point(m, d.data(), Index(d.size()), p, qp, &po, &qo);
  Eigen::VectorXd y(6);
  y << po, so3::log(Quaternion<double>(q0.conjugate() * qo));
  return y;
}

// Central differences of skin_point w.r.t. driver k's 13 columns and the point's 6 columns.
inline Eigen::MatrixXd fd_driver_jacobian(SkinMethod m, const Drivers& d, Index k,
                                          const Vector3<double>& p, const Quaternion<double>& qp) {
  Vector3<double> p0;
  Quaternion<double> q0;
  skin_point(m, d.data(), Index(d.size()), p, qp, &p0, &q0);
  return central_jacobian(
      [&](const Eigen::VectorXd& e) -> Eigen::VectorXd {
        Drivers dd = d;
        auto& x = dd[static_cast<std::size_t>(k)];
        x.x_ref += e.segment<3>(0);
        x.q_ref = x.q_ref * so3::exp(Vector3<double>(e.segment<3>(3)));
        x.x_t += e.segment<3>(6);
        x.q_t = x.q_t * so3::exp(Vector3<double>(e.segment<3>(9)));
        x.weight += e(12);
        return output_tangent(m, dd, p, qp, q0);
      },
      Eigen::VectorXd::Zero(13));
}
inline Eigen::MatrixXd fd_point_jacobian(SkinMethod m, const Drivers& d, const Vector3<double>& p,
                                         const Quaternion<double>& qp) {
  Vector3<double> p0;
  Quaternion<double> q0;
  skin_point(m, d.data(), Index(d.size()), p, qp, &p0, &q0);
  return central_jacobian(
      [&](const Eigen::VectorXd& e) -> Eigen::VectorXd {
        return output_tangent(m, d, Vector3<double>(p + e.head<3>()),
                              Quaternion<double>(qp * so3::exp(Vector3<double>(e.tail<3>()))), q0);
      },
      Eigen::VectorXd::Zero(6));
}

// A small random scene for the batched functions: T frames, N nodes (random poses, quaternions
// deliberately not unit, to exercise normalisation on entry), a random graph with K neighbours
// (some rows short), P points anchored near random nodes.
struct SkinScene {
  Index T = 0, N = 0, K = 0, P = 0;
  std::vector<double> positions, quats, graph_w, points, point_quats, sigma;
  std::vector<std::int32_t> graph_idx, anchor, t_ref;
};

inline SkinScene random_scene(Rng& rng, Index T, Index N, Index K, Index P) {
  SkinScene s;
  s.T = T;
  s.N = N;
  s.K = K;
  s.P = P;
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i) {
      const Vector3<double> x = rng.vec3(2.0);
      const Quaternion<double> q = rng.quaternion();
      const double scale = rng.uniform(0.5, 2.0);
      s.positions.insert(s.positions.end(), {x(0), x(1), x(2)});
      s.quats.insert(s.quats.end(), {scale * q.w(), scale * q.x(), scale * q.y(), scale * q.z()});
    }
  for (Index i = 0; i < N; ++i) {
    const int deg = rng.integer(0, int(K));
    std::vector<std::int32_t> row;
    while (Index(row.size()) < deg) {
      const std::int32_t j = rng.integer(0, int(N) - 1);
      if (j == i) continue;
      bool dup = false;
      for (auto r : row) dup |= r == j;
      if (!dup) row.push_back(j);
    }
    for (Index k = 0; k < K; ++k) {
      s.graph_idx.push_back(k < deg ? row[k] : -1);
      s.graph_w.push_back(k < deg ? 1.0 / deg : 0.0);
    }
  }
  for (Index p = 0; p < P; ++p) {
    const std::int32_t a = rng.integer(0, int(N) - 1);
    const std::int32_t tr = rng.integer(0, int(T) - 1);
    s.anchor.push_back(a);
    s.t_ref.push_back(tr);
    const Vector3<double> x = Eigen::Map<const Vector3<double>>(&s.positions[(tr * N + a) * 3]) +
                              rng.vec3(0.5);
    s.points.insert(s.points.end(), {x(0), x(1), x(2)});
    const Quaternion<double> q = rng.quaternion();
    s.point_quats.insert(s.point_quats.end(), {1.3 * q.w(), 1.3 * q.x(), 1.3 * q.y(), 1.3 * q.z()});
  }
  for (Index i = 0; i < N; ++i) s.sigma.push_back(rng.uniform(0.8, 2.0));
  return s;
}

}  // namespace smg::test
