// Tests of smg/skin/blend_point.hpp: DQB and LBS of one point — semantics against independent
// references, the invariances the issue names, and every Jacobian against central differences
// (double), AutoDiffScalar and the vector-Jacobian product; float against double.
#include <doctest/doctest.h>

#include "skin/skin_test_support.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

using smg::SkinMethod;
using smg::test::Drivers;

namespace {
constexpr SkinMethod kPointMethods[] = {SkinMethod::dqb, SkinMethod::lbs};

void blend(SkinMethod m, const Drivers& d, const Vector3<double>& p, const Quaternion<double>& qp,
           Vector3<double>* po, Quaternion<double>* qo) {
  smg::skin_point(m, d.data(), Index(d.size()), p, qp, po, qo);
}
}  // namespace

TEST_CASE("DQB matches a reference built from core dual quaternions; LBS matches matrix blending") {
  SMG_TEST_RNG(rng, 501);
  for (int trial = 0; trial < 200; ++trial) {
    const int D = rng.integer(1, 9);
    const Drivers d = smg::test::random_drivers(rng, D);
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    Vector3<double> po, pr;
    Quaternion<double> qo, qr;
    blend(SkinMethod::dqb, d, p, qp, &po, &qo);
    smg::test::reference_dqb(d, p, qp, &pr, &qr);
    CHECK((po - pr).norm() < 1e-13 * (1 + pr.norm()));
    CHECK((qo.coeffs() - qr.coeffs()).norm() < 1e-14);
    CHECK(std::abs(qo.norm() - 1) < 1e-14);
    Vector3<double> pl;
    Quaternion<double> ql;
    blend(SkinMethod::lbs, d, p, qp, &pl, &ql);
    CHECK((pl - smg::test::reference_lbs(d, p)).norm() < 1e-13 * (1 + pl.norm()));
    CHECK((ql.coeffs() - qo.coeffs()).norm() == 0);  // LBS shares DQB's rotation output (S12)
  }
}

TEST_CASE("all drivers with the same motion give exactly that motion") {
  SMG_TEST_RNG(rng, 502);
  for (int trial = 0; trial < 50; ++trial) {
    // Motion G = (g, u): every node's pose at t is G applied to its pose at t_ref.
    const Quaternion<double> g = rng.quaternion();
    const Vector3<double> u = rng.vec3(5);
    const int D = rng.integer(1, 8);
    Drivers d = smg::test::random_drivers(rng, D);
    for (auto& x : d) {
      x.x_t = g * x.x_ref + u;
      x.q_t = g * x.q_ref;
    }
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    for (SkinMethod m : kPointMethods) {
      const std::string method_name = smg::to_string(m);
      CAPTURE(method_name);
      Vector3<double> po;
      Quaternion<double> qo;
      blend(m, d, p, qp, &po, &qo);
      CHECK((po - (g * p + u)).norm() < 1e-13 * (1 + po.norm()));
      CHECK(smg::so3::angular_distance(qo, Quaternion<double>(g * qp)) < 1e-14);
    }
  }
}

TEST_CASE("a weight of 1 (others 0) gives that driver's motion") {
  SMG_TEST_RNG(rng, 503);
  for (int trial = 0; trial < 50; ++trial) {
    const int D = rng.integer(2, 8);
    Drivers d = smg::test::random_drivers(rng, D);
    const int one = rng.integer(0, D - 1);
    for (int k = 0; k < D; ++k) d[k].weight = k == one ? 1.0 : 0.0;
    const auto& x = d[one];
    const Quaternion<double> r = x.q_t * x.q_ref.conjugate();
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    for (SkinMethod m : kPointMethods) {
      Vector3<double> po;
      Quaternion<double> qo;
      blend(m, d, p, qp, &po, &qo);
      CHECK((po - (r * (p - x.x_ref) + x.x_t)).norm() < 1e-13);
      CHECK(smg::so3::angular_distance(qo, Quaternion<double>(r * qp)) < 1e-14);
    }
  }
}

TEST_CASE("negating any input quaternion changes nothing") {
  SMG_TEST_RNG(rng, 504);
  for (int trial = 0; trial < 50; ++trial) {
    const int D = rng.integer(1, 8);
    const Drivers d = smg::test::random_drivers(rng, D);
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    for (SkinMethod m : kPointMethods) {
      Vector3<double> p0;
      Quaternion<double> q0;
      smg::SkinDriverJacobian<double> J0[8], J1[8];
      smg::SkinPointJacobian<double> Jp0, Jp1;
      smg::skin_point(m, d.data(), D, p, qp, &p0, &q0, J0, &Jp0);
      for (int k = 0; k < D; ++k)
        for (int which = 0; which < 2; ++which) {
          Drivers e = d;
          auto& q = which == 0 ? e[k].q_ref : e[k].q_t;
          q.coeffs() = -q.coeffs();
          Vector3<double> p1;
          Quaternion<double> q1;
          smg::skin_point(m, e.data(), D, p, qp, &p1, &q1, J1, &Jp1);
          // Bit-identical: signs are aligned to the canonical pivot (docs/math/skin.md (S8)).
          CHECK((p1 == p0));
          CHECK((q1.coeffs() == q0.coeffs()));
          for (int j = 0; j < D; ++j) CHECK((J1[j] == J0[j]));
          CHECK((Jp1 == Jp0));
        }
      // The point's own quaternion: q' = c0 ⊗ q_p is linear in q_p, so it flips with it.
      Vector3<double> p1;
      Quaternion<double> q1;
      smg::skin_point(m, d.data(), D, p, Quaternion<double>(-qp.coeffs()), &p1, &q1, J1, &Jp1);
      CHECK((p1 == p0));
      CHECK((q1.coeffs() == -q0.coeffs()));
      for (int j = 0; j < D; ++j) CHECK((J1[j] == J0[j]));
      CHECK((Jp1 == Jp0));
    }
  }
}

TEST_CASE("Jacobians of DQB and LBS against central differences") {
  SMG_TEST_RNG(rng, 505);
  for (int trial = 0; trial < 30; ++trial) {
    const int D = rng.integer(1, 6);
    const Drivers d = smg::test::random_drivers(rng, D);
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    for (SkinMethod m : kPointMethods) {
      const std::string method_name = smg::to_string(m);
      CAPTURE(method_name);
      smg::SkinDriverJacobian<double> J[6];
      smg::SkinPointJacobian<double> Jp;
      smg::skin_point(m, d.data(), D, p, qp, nullptr, nullptr, J, &Jp);
      for (int k = 0; k < D; ++k) {
        CAPTURE(k);
        CHECK(relative_error(J[k], smg::test::fd_driver_jacobian(m, d, k, p, qp)) < 1e-8);
      }
      CHECK(relative_error(Jp, smg::test::fd_point_jacobian(m, d, p, qp)) < 1e-8);
      // The structure docs/math/skin.md states: φ_ref = −φ_t columns; rotation rows do not
      // depend on positions; d θ'/d φ_p = I.
      for (int k = 0; k < D; ++k) {
        CHECK((J[k].middleCols<3>(3) == -J[k].middleCols<3>(9)));
        CHECK(J[k].block<3, 3>(3, 0).isZero(0));
        CHECK(J[k].block<3, 3>(3, 6).isZero(0));
      }
      CHECK(Jp.block<3, 3>(3, 3).isIdentity(0));
      CHECK(Jp.block<3, 3>(0, 3).isZero(0));
      if (m == SkinMethod::dqb) {
        // DQB is invariant to scaling all weights: Σ_k w_k ∂/∂w_k = 0.
        Eigen::Matrix<double, 6, 1> euler = Eigen::Matrix<double, 6, 1>::Zero();
        for (int k = 0; k < D; ++k) euler += d[k].weight * J[k].col(12);
        CHECK(euler.norm() < 1e-13 * (1 + J[0].col(12).norm()));
      }
    }
  }
}

TEST_CASE("Jacobians against AutoDiffScalar") {
  using smg::test::AD;
  SMG_TEST_RNG(rng, 506);
  for (int trial = 0; trial < 6; ++trial) {
    const int D = rng.integer(1, 4);
    const Drivers d = smg::test::random_drivers(rng, D);
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    const Index n = D * 13 + 6;
    for (SkinMethod m : kPointMethods) {
      const std::string method_name = smg::to_string(m);
      CAPTURE(method_name);
      // Every input as base ⊕ AD variable (rotations: q ⊗ Exp(φ) at φ = 0).
      std::vector<smg::SkinDriver<AD>> da(static_cast<std::size_t>(D));
      auto rot = [&](const Quaternion<double>& q, Index offset) {
        const Vector3<AD> phi = smg::test::ad_variables<3>(Vector3<double>::Zero(), n, offset);
        return Quaternion<AD>(q.cast<AD>() * smg::so3::exp(phi));
      };
      for (int k = 0; k < D; ++k) {
        const Index o = k * 13;
        da[k].x_ref = smg::test::ad_variables<3>(d[k].x_ref, n, o);
        da[k].q_ref = rot(d[k].q_ref, o + 3);
        da[k].x_t = smg::test::ad_variables<3>(d[k].x_t, n, o + 6);
        da[k].q_t = rot(d[k].q_t, o + 9);
        da[k].weight = AD(d[k].weight, n, o + 12);
      }
      const Vector3<AD> pa = smg::test::ad_variables<3>(p, n, D * 13);
      const Quaternion<AD> qa = rot(qp, D * 13 + 3);
      Vector3<AD> po;
      Quaternion<AD> qo;
      smg::skin_point(m, da.data(), D, pa, qa, &po, &qo);
      Vector3<double> p0;
      Quaternion<double> q0;
      smg::SkinDriverJacobian<double> J[4];
      smg::SkinPointJacobian<double> Jp;
      smg::skin_point(m, d.data(), D, p, qp, &p0, &q0, J, &Jp);
      const Vector3<AD> theta = smg::so3::log(Quaternion<AD>(q0.cast<AD>().conjugate() * qo));
      Eigen::Matrix<AD, 6, 1> y;
      y << po, theta;
      const MatrixXd Jad = smg::test::ad_jacobian<6>(y, n);
      for (int k = 0; k < D; ++k) CHECK(relative_error(J[k], Jad.middleCols(k * 13, 13)) < 1e-12);
      CHECK(relative_error(Jp, Jad.rightCols(6)) < 1e-12);
    }
  }
}

TEST_CASE("the vector-Jacobian product equals Jᵀ g") {
  SMG_TEST_RNG(rng, 507);
  for (int trial = 0; trial < 30; ++trial) {
    const int D = rng.integer(1, 8);
    const Drivers d = smg::test::random_drivers(rng, D);
    const Vector3<double> p = rng.vec3(3), gp = rng.vec3(), gr = rng.vec3();
    const Quaternion<double> qp = rng.quaternion();
    Eigen::Matrix<double, 6, 1> g;
    g << gp, gr;
    for (SkinMethod m : kPointMethods) {
      smg::SkinDriverJacobian<double> J[8];
      smg::SkinPointJacobian<double> Jp;
      smg::skin_point(m, d.data(), D, p, qp, nullptr, nullptr, J, &Jp);
      smg::SkinDriverGradient<double> G[8];
      Vector3<double> g_p, g_phi;
      smg::skin_point_vjp(m, d.data(), D, p, qp, gp, gr, G, &g_p, &g_phi);
      for (int k = 0; k < D; ++k) {
        Eigen::Matrix<double, 13, 1> v;
        v << G[k].x_ref, G[k].phi_ref, G[k].x_t, G[k].phi_t, G[k].weight;
        CHECK(relative_error(v, J[k].transpose() * g) < 1e-14);
      }
      Eigen::Matrix<double, 6, 1> vp;
      vp << g_p, g_phi;
      CHECK(relative_error(vp, Jp.transpose() * g) < 1e-14);
    }
  }
}

TEST_CASE("float against double: values and Jacobians") {
  SMG_TEST_RNG(rng, 508);
  double worst_value = 0, worst_jac = 0;
  for (int trial = 0; trial < 50; ++trial) {
    const int D = rng.integer(1, 8);
    const Drivers d = smg::test::random_drivers(rng, D);
    std::vector<smg::SkinDriver<float>> f(d.size());
    for (int k = 0; k < D; ++k) {
      f[k].x_ref = d[k].x_ref.cast<float>();
      f[k].q_ref = d[k].q_ref.cast<float>();
      f[k].x_t = d[k].x_t.cast<float>();
      f[k].q_t = d[k].q_t.cast<float>();
      f[k].weight = float(d[k].weight);
    }
    const Vector3<double> p = rng.vec3(3);
    const Quaternion<double> qp = rng.quaternion();
    for (SkinMethod m : kPointMethods) {
      Vector3<double> pd;
      Quaternion<double> qd;
      smg::SkinDriverJacobian<double> Jd[8];
      smg::skin_point(m, d.data(), D, p, qp, &pd, &qd, Jd);
      Vector3<float> pf;
      Quaternion<float> qf;
      smg::SkinDriverJacobian<float> Jf[8];
      smg::skin_point(m, f.data(), D, Vector3<float>(p.cast<float>()), qp.cast<float>(), &pf, &qf, Jf);
      worst_value = std::max({worst_value, relative_error(pf, pd), relative_error(qf.coeffs(), qd.coeffs())});
      for (int k = 0; k < D; ++k) worst_jac = std::max(worst_jac, relative_error(Jf[k], Jd[k]));
    }
  }
  MESSAGE("float vs double: value ", worst_value, ", Jacobian ", worst_jac);
  CHECK(worst_value < 2e-6);
  CHECK(worst_jac < 5e-6);
}
