// Tests of the residual + Jacobian forms (carap_residuals.hpp, lrm_residuals.hpp): they sum to
// the energies, 2 Jᵀ r equals the gradients of the fast kernels, blocks match finite
// differences, and a small Levenberg-Marquardt solver built only on them decreases C-ARAP + LRM.
#include <doctest/doctest.h>

#include <cmath>
#include <mutex>
#include <vector>

#include <Eigen/Dense>

#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/prelude.hpp"

using smg::test::Scene;

TEST_CASE("C-ARAP residuals: sum of squares, 2 J^T r and the block count") {
  SMG_TEST_RNG(rng, 701);
  const Scene<double> s = smg::test::random_scene(9, 12, 4, rng);
  smg::CarapOptions o;
  o.gaps = {{1, 1.0}, {3, 0.5}};
  o.normalization = smg::Normalization::mean;
  o.weight = 2.0;
  std::vector<double> gx(s.x.size(), 0.0), gr(s.x.size(), 0.0);
  const double e = smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o,
                                      {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N});
  std::vector<double> hx(s.x.size(), 0.0), hr(s.x.size(), 0.0);
  double sum = 0;
  Index blocks = 0;
  smg::ParallelOptions par;
  par.threads = 1;
  smg::for_each_carap_residual<double>(
      s.positions(), s.rotations(), s.confidence(), s.graph(), o,
      [&](const smg::CarapResidualBlock<double>& b, Index) {
        sum += b.r.squaredNorm();
        ++blocks;
        smg::add_carap_block_gradient<double>(b, {hx.data(), s.T, s.N}, {hr.data(), s.T, s.N});
      },
      true, par);
  CHECK(blocks == smg::carap_residual_count(s.graph(), s.T, o));
  CHECK(sum == doctest::Approx(e).epsilon(1e-12));
  CHECK(smg::test::relative_error(hx, gx) < 1e-12);
  CHECK(smg::test::relative_error(hr, gr) < 1e-12);
}

TEST_CASE("C-ARAP residual blocks: Jacobians match central finite differences") {
  SMG_TEST_RNG(rng, 702);
  Scene<double> s = smg::test::random_scene(6, 8, 3, rng);
  smg::CarapOptions o;
  const double h = 1e-6;
  for (int rep = 0; rep < 12; ++rep) {
    const Index g = rng.integer(0, 2), i = rng.integer(0, int(s.N) - 1), k = 0;
    const Index t = rng.integer(0, int(s.T - 1 - o.gaps[g].delta));
    smg::CarapResidualBlock<double> b;
    REQUIRE(smg::carap_residual_block<double>(s.positions(), s.rotations(), s.confidence(),
                                              s.graph(), o, g, t, i, k, b));
    auto residual = [&](const Scene<double>& p) {
      smg::CarapResidualBlock<double> c;
      smg::carap_residual_block<double>(p.positions(), p.rotations(), p.confidence(), p.graph(),
                                        o, g, t, i, k, c, false);
      return Eigen::Vector4d(c.r);
    };
    auto check_position = [&](Index frame, Index node, const Eigen::Matrix<double, 4, 3>& J) {
      Eigen::Matrix<double, 4, 3> F;
      for (int c = 0; c < 3; ++c) {
        Scene<double> p = s, m = s;
        p.x[(frame * s.N + node) * 3 + c] += h;
        m.x[(frame * s.N + node) * 3 + c] -= h;
        F.col(c) = (residual(p) - residual(m)) / (2 * h);
      }
      CHECK((J - F).norm() <= 1e-7 * std::max(1.0, F.norm()));
    };
    auto check_rotation = [&](Index frame, const Eigen::Matrix<double, 4, 3>& J) {
      Eigen::Matrix<double, 4, 3> F;
      for (int c = 0; c < 3; ++c) {
        Scene<double> p = s, m = s;
        Vector3<double> d = Vector3<double>::Zero();
        d(c) = h;
        p.set_rot(frame, i, s.rot(frame, i) * smg::so3::exp(d));
        m.set_rot(frame, i, s.rot(frame, i) * smg::so3::exp(Vector3<double>(-d)));
        F.col(c) = (residual(p) - residual(m)) / (2 * h);
      }
      CHECK((J - F).norm() <= 1e-7 * std::max(1.0, F.norm()));
    };
    check_position(b.t, b.i, b.J_xi_t);
    check_position(b.t, b.j, b.J_xj_t);
    check_position(b.s, b.i, b.J_xi_s);
    check_position(b.s, b.j, b.J_xj_s);
    check_rotation(b.t, b.J_rot_i_t);
    check_rotation(b.s, b.J_rot_i_s);
  }
  // Addresses that name no term.
  smg::CarapResidualBlock<double> b;
  CHECK(!smg::carap_residual_block<double>(s.positions(), s.rotations(), s.confidence(), s.graph(),
                                           o, 2, s.T - 4, 0, 0, b));
}

TEST_CASE("LRM residuals: block energies, IRLS sum of squares and 2 J_f^T f") {
  SMG_TEST_RNG(rng, 703);
  const Scene<double> s = smg::test::random_scene(6, 14, 5, rng);
  for (double delta : {0.02, 50.0})
    for (bool detach : {false, true}) {
      smg::LrmOptions o = smg::test::lrm_options(delta, detach);
      o.weight = 1.5;
      CAPTURE(delta);
      CAPTURE(detach);
      std::vector<double> g(s.x.size(), 0.0), h(s.x.size(), 0.0);
      const double e = smg::lrm<double>(s.positions(), s.confidence(), s.graph(), o,
                                        {g.data(), s.T, s.N});
      double sum_e = 0, sum_f = 0;
      std::mutex m;
      smg::for_each_lrm_residual<double>(
          s.positions(), s.confidence(), s.graph(), o,
          [&](const smg::LrmResidualBlock<double>& b, Index) {
            std::lock_guard<std::mutex> lock(m);  // order does not matter to 1e-12 here
            sum_e += b.energy;
            sum_f += b.r.squaredNorm();
            smg::add_lrm_block_gradient<double>(b, {h.data(), s.T, s.N});
          });
      CHECK(sum_e == doctest::Approx(e).epsilon(1e-12));
      if (delta > 1) CHECK(sum_f == doctest::Approx(e).epsilon(1e-12));  // quadratic zone
      // In the linear zone ½ ψ r² = ½ δ r < δ (r − δ/2): the IRLS sum understates the value...
      if (delta < 1) CHECK(sum_f < e);
      CHECK(smg::test::relative_error(h, g) < 1e-10);  // ...but its gradient is exact
    }
}

TEST_CASE("LRM residual blocks: Jacobians match finite differences of the raw residuals") {
  SMG_TEST_RNG(rng, 704);
  Scene<double> s = smg::test::random_scene(5, 10, 5, rng);
  smg::test::random_graph(s, 5, 3, rng);
  const double h = 1e-6;
  for (bool detach : {false, true}) {
    const smg::LrmOptions o = smg::test::lrm_options(0.02, detach);
    for (Index t : {Index(1), s.T - 1})
      for (Index i = 0; i < s.N; i += 3) {
        CAPTURE(detach);
        CAPTURE(t);
        CAPTURE(i);
        smg::LrmResidualBlock<double> b;
        REQUIRE(smg::lrm_residual_block<double>(s.positions(), s.confidence(), s.graph(), o, t, i,
                                                b));
        const Index n = static_cast<Index>(b.neighbors.size());
        // Raw-residual Jacobians w.r.t. the frames the block touches: J_f / √(ŵψ/2).
        Eigen::MatrixXd Jx = b.J_x, Ju = b.J_u;
        for (Index k = 0; k < n; ++k) {
          const double sk = std::sqrt(b.weight(k) * b.irls(k) * 0.5);
          Jx.middleRows(3 * k, 3) /= sk;
          Ju.middleRows(3 * k, 3) /= sk;
        }
        for (Index m = 0; m < n; ++m) {
          const Index j = b.neighbors[static_cast<std::size_t>(m)];
          std::vector<Index> frames = {b.t};
          for (Index f : {b.frames.plus, b.frames.minus})
            if (f != b.t) frames.push_back(f);  // at t = T − 1, plus is t itself
          for (Index frame : frames) {
            Eigen::MatrixXd expect = Eigen::MatrixXd::Zero(3 * n, 3);
            if (frame == b.t) expect += Jx.middleCols(3 * m, 3);
            if (frame == b.frames.plus) expect += Ju.middleCols(3 * m, 3);
            if (frame == b.frames.minus) expect -= Ju.middleCols(3 * m, 3);
            Eigen::MatrixXd F(3 * n, 3);
            for (int c = 0; c < 3; ++c) {
              Scene<double> p = s, q = s;
              p.x[(frame * s.N + j) * 3 + c] += h;
              q.x[(frame * s.N + j) * 3 + c] -= h;
              smg::LrmResidualBlock<double> bp, bq;
              smg::lrm_residual_block<double>(p.positions(), p.confidence(), p.graph(), o, t, i,
                                              bp, false);
              smg::lrm_residual_block<double>(q.positions(), q.confidence(), q.graph(), o, t, i,
                                              bq, false);
              F.col(c) = (bp.raw - bq.raw) / (2 * h);
            }
            // FD moves ω, so only the exact Jacobian is compared here; the detached one is
            // checked contracted (2 J_fᵀ f against the detached kernel gradient) above.
            if (detach) continue;
            CHECK((expect - F).norm() <= 1e-7 * std::max(1.0, F.norm()));
          }
        }
      }
  }
}

TEST_CASE("Levenberg-Marquardt on the residual forms decreases C-ARAP + LRM") {
  // A small solver written only against the residual API: dense J, (JᵀJ + λ diag) δ = −Jᵀr,
  // positions updated additively, rotations by q ⊗ Exp(δφ) (the right tangent).
  SMG_TEST_RNG(rng, 705);
  Scene<double> s = smg::test::rigid_scene(5, 10, 4, 0.05, Vector3<double>(0.02, 0, 0), rng);
  for (double& v : s.x) v += rng.uniform(-0.03, 0.03);  // non-rigid noise
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i) s.set_rot(t, i, s.rot(t, i) * rng.rotation_with_angle(0.2));
  smg::CarapOptions co;
  co.gaps = {{1, 1.0}, {2, 1.0}};
  smg::LrmOptions lo;
  lo.huber_delta = 0.01;
  const Index TN = s.T * s.N, nv = 6 * TN;
  auto energy = [&](const Scene<double>& p) {
    return smg::carap<double>(p.positions(), p.rotations(), {}, p.graph(), co) +
           smg::lrm<double>(p.positions(), {}, p.graph(), lo);
  };
  auto pos_col = [&](Index t, Index i) { return 3 * (t * s.N + i); };
  auto rot_col = [&](Index t, Index i) { return 3 * TN + 3 * (t * s.N + i); };
  smg::ParallelOptions serial;
  serial.threads = 1;
  double e = energy(s), lambda = 1e-3;
  const double e0 = e;
  int accepted = 0;
  for (int it = 0; it < 25; ++it) {
    std::vector<Eigen::RowVectorXd> rows;
    std::vector<double> res;
    smg::for_each_carap_residual<double>(
        s.positions(), s.rotations(), {}, s.graph(), co,
        [&](const smg::CarapResidualBlock<double>& b, Index) {
          for (int r = 0; r < 4; ++r) {
            Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(nv);
            row.segment<3>(pos_col(b.t, b.i)) += b.J_xi_t.row(r);
            row.segment<3>(pos_col(b.t, b.j)) += b.J_xj_t.row(r);
            row.segment<3>(pos_col(b.s, b.i)) += b.J_xi_s.row(r);
            row.segment<3>(pos_col(b.s, b.j)) += b.J_xj_s.row(r);
            row.segment<3>(rot_col(b.t, b.i)) += b.J_rot_i_t.row(r);
            row.segment<3>(rot_col(b.s, b.i)) += b.J_rot_i_s.row(r);
            rows.push_back(row);
            res.push_back(b.r(r));
          }
        },
        true, serial);
    smg::for_each_lrm_residual<double>(
        s.positions(), {}, s.graph(), lo,
        [&](const smg::LrmResidualBlock<double>& b, Index) {
          const Index n = static_cast<Index>(b.neighbors.size());
          for (Index r = 0; r < 3 * n; ++r) {
            Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(nv);
            for (Index m = 0; m < n; ++m) {
              const Index j = b.neighbors[static_cast<std::size_t>(m)];
              row.segment<3>(pos_col(b.t, j)) += b.J_x.block(r, 3 * m, 1, 3);
              if (b.frames.moving) {
                row.segment<3>(pos_col(b.frames.plus, j)) += b.J_u.block(r, 3 * m, 1, 3);
                row.segment<3>(pos_col(b.frames.minus, j)) -= b.J_u.block(r, 3 * m, 1, 3);
              }
            }
            rows.push_back(row);
            res.push_back(b.r(r));
          }
        },
        true, serial);
    Eigen::MatrixXd J(rows.size(), nv);
    for (std::size_t r = 0; r < rows.size(); ++r) J.row(static_cast<Index>(r)) = rows[r];
    const Eigen::VectorXd rv = Eigen::Map<const Eigen::VectorXd>(res.data(), Index(res.size()));
    const Eigen::MatrixXd H = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * rv;
    for (int tries = 0; tries < 10; ++tries) {
      Eigen::MatrixXd A = H;
      A.diagonal() += lambda * (H.diagonal().array() + 1e-9).matrix();
      const Eigen::VectorXd d = A.ldlt().solve(-g);
      Scene<double> p = s;
      for (Index k = 0; k < 3 * TN; ++k) p.x[k] += d(k);
      for (Index t = 0; t < s.T; ++t)
        for (Index i = 0; i < s.N; ++i)
          p.set_rot(t, i, s.rot(t, i) * smg::so3::exp(Vector3<double>(d.segment<3>(rot_col(t, i)))));
      const double ep = energy(p);
      if (ep < e) {
        s = p;
        e = ep;
        lambda = std::max(lambda / 10, 1e-9);
        ++accepted;
        break;
      }
      lambda *= 10;
    }
  }
  CAPTURE(e0);
  CAPTURE(e);
  CHECK(accepted >= 5);
  CHECK(e < 1e-2 * e0);
}

TEST_CASE("quaternion manifold (right, full angle): plus/minus and their Jacobians") {
  SMG_TEST_RNG(rng, 706);
  for (int rep = 0; rep < 20; ++rep) {
    const Quaternion<double> q = rng.quaternion();
    double qa[4] = {q.w(), q.x(), q.y(), q.z()};
    const Vector3<double> d = rng.vec3(1.0);
    double out[4], back[3];
    smg::quaternion_manifold::plus(qa, d.data(), out);
    smg::quaternion_manifold::minus(out, qa, back);
    CHECK((Vector3<double>(back[0], back[1], back[2]) - d).norm() < 1e-12);
    // plus = q ⊗ Exp(δ): a right, full-angle perturbation (Ceres's is left, half-angle).
    const Quaternion<double> expect = q * smg::so3::exp(d);
    CHECK(std::min((smg::to_wxyz(expect) - Eigen::Vector4d(out)).norm(),
                   (smg::to_wxyz(expect) + Eigen::Vector4d(out)).norm()) < 1e-14);
    // Jacobians against central differences.
    const double h = 1e-6;
    Eigen::Matrix<double, 4, 3, Eigen::RowMajor> Jp;
    smg::quaternion_manifold::plus_jacobian(qa, Jp.data());
    Eigen::Matrix<double, 3, 4, Eigen::RowMajor> Jm;
    smg::quaternion_manifold::minus_jacobian(qa, Jm.data());
    Eigen::Matrix<double, 4, 3> Fp;
    for (int c = 0; c < 3; ++c) {
      double dp[3] = {0, 0, 0}, dm[3] = {0, 0, 0}, op[4], om[4];
      dp[c] = h;
      dm[c] = -h;
      smg::quaternion_manifold::plus(qa, dp, op);
      smg::quaternion_manifold::plus(qa, dm, om);
      Fp.col(c) = (Eigen::Vector4d(op) - Eigen::Vector4d(om)) / (2 * h);
    }
    CHECK((Jp - Fp).norm() < 1e-9);
    Eigen::Matrix<double, 3, 4> Fm;
    for (int c = 0; c < 4; ++c) {
      double yp[4], ym[4], rp[3], rm[3];
      for (int k = 0; k < 4; ++k) yp[k] = ym[k] = qa[k];
      yp[c] += h;
      ym[c] -= h;
      smg::quaternion_manifold::minus(yp, qa, rp);
      smg::quaternion_manifold::minus(ym, qa, rm);
      Fm.col(c) = (Eigen::Vector3d(rp) - Eigen::Vector3d(rm)) / (2 * h);
    }
    // Off the unit sphere minus only sees the direction of y: compare on the tangent of |q| = 1.
    CHECK(((Jm - Fm) * Jp).norm() < 1e-9);
    CHECK((Jm * Jp - Eigen::Matrix3d::Identity()).norm() < 1e-14);
    // Lifting a right-tangent cost Jacobian to the ambient 4-vector and back.
    const Eigen::Matrix<double, 2, 3> G = Eigen::Matrix<double, 2, 3>::Random();
    CHECK((smg::quaternion_manifold::ambient_jacobian(G, q) * Jp - G).norm() < 1e-14);
  }
}
