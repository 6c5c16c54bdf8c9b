// Tests of smg/skin/weights_point.hpp: distance-aware skinning weights of one point — values,
// the underflow-safe softmax and its fallback, Jacobians against central differences and
// AutoDiffScalar, the vector-Jacobian product, float against double.
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "skin/skin_test_support.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

namespace {
struct Case {
  Vector3<double> p;
  std::vector<Vector3<double>> x;
  std::vector<double> sigma;
};
Case random_case(smg::test::Rng& rng, int D, double spread = 1.0) {
  Case c;
  c.p = rng.vec3(spread);
  for (int k = 0; k < D; ++k) {
    c.x.push_back(rng.vec3(spread));
    c.sigma.push_back(rng.uniform(0.5, 1.5) * spread);
  }
  return c;
}
VectorXd weights(const Case& c) {
  VectorXd w(c.x.size());
  smg::skinning_weights_point<double>(c.p, Index(c.x.size()), c.x.data(), c.sigma.data(), w.data());
  return w;
}
}  // namespace

TEST_CASE("weights are the normalised exp(-|p - x_k|^2 / 2 sigma_k^2)") {
  SMG_TEST_RNG(rng, 511);
  for (int trial = 0; trial < 100; ++trial) {
    const int D = rng.integer(1, 17);
    const Case c = random_case(rng, D);
    const VectorXd w = weights(c);
    VectorXd direct(D);
    for (int k = 0; k < D; ++k)
      direct(k) = std::exp(-(c.p - c.x[k]).squaredNorm() / (2 * c.sigma[k] * c.sigma[k]));
    direct /= direct.sum();
    CHECK(relative_error(w, direct) < 1e-15);
    CHECK(std::abs(w.sum() - 1) < 1e-15);
    CHECK(w.minCoeff() >= 0);
  }
}

TEST_CASE("weights stay exact when every exp underflows; defined fallback when every logit is -inf") {
  // Far from both drivers: exp(-l) underflows to 0 for both, the naive ratio would be 0/0.
  const Vector3<double> p(0, 0, 0);
  std::vector<Vector3<double>> x = {Vector3<double>(100, 0, 0), Vector3<double>(0, 0, 0)};
  // l_0 = -5000, l_1 = -5000 + ln 3 with sigma chosen so: |p-x_1|^2/(2 s^2) = 5000 - ln 3.
  const double d1 = 1.0;
  const double s1 = d1 / std::sqrt(2 * (5000 - std::log(3.0)));
  std::vector<double> sigma = {1.0, s1};
  CHECK(std::exp(-5000.0) == 0.0);
  x[1] = Vector3<double>(d1, 0, 0);
  double w[2];
  CHECK_FALSE(smg::skinning_weights_point<double>(p, 2, x.data(), sigma.data(), w));
  CHECK(std::abs(w[0] - 0.25) < 1e-12);
  CHECK(std::abs(w[1] - 0.75) < 1e-12);

  // One driver's scaled distance overflows (logit -inf, weight exactly 0), the other is finite.
  std::vector<double> sigma2 = {1e-300, 1.0};
  smg::Vector3<double> Jp[2], Jx[4];
  double Js[4];
  CHECK_FALSE(smg::skinning_weights_point<double>(p, 2, x.data(), sigma2.data(), w, Jp, Jx, Js));
  CHECK(w[0] == 0.0);
  CHECK(w[1] == 1.0);
  for (int j = 0; j < 4; ++j) CHECK(std::isfinite(Js[j]));
  for (int j = 0; j < 4; ++j) CHECK(Jx[j].allFinite());

  // Every logit -inf: all weight on driver 0 (the anchor), zero derivatives, reported.
  std::vector<double> tiny = {1e-300, 1e-300};
  CHECK(smg::skinning_weights_point<double>(p, 2, x.data(), tiny.data(), w, Jp, Jx, Js));
  CHECK(w[0] == 1.0);
  CHECK(w[1] == 0.0);
  for (int j = 0; j < 2; ++j) CHECK(Jp[j].isZero(0));
  for (int j = 0; j < 4; ++j) CHECK(Jx[j].isZero(0));
  for (int j = 0; j < 4; ++j) CHECK(Js[j] == 0.0);
  double g_w[2] = {1.0, -2.0}, gs[2];
  Vector3<double> gp = Vector3<double>::Zero(), gx[2];
  smg::skinning_weights_point_vjp<double>(p, 2, x.data(), tiny.data(), w, g_w, &gp, gx, gs);
  CHECK(gp.isZero(0));
  CHECK((gx[0].isZero(0) && gx[1].isZero(0) && gs[0] == 0 && gs[1] == 0));

  // Float: the same fallback at float's overflow threshold.
  const Vector3<float> pf(0, 0, 0);
  std::vector<Vector3<float>> xf = {Vector3<float>(1, 0, 0), Vector3<float>(0, 2, 0)};
  std::vector<float> sf = {1e-25f, 1e-25f};
  float wf[2];
  CHECK(smg::skinning_weights_point<float>(pf, 2, xf.data(), sf.data(), wf));
  CHECK(wf[0] == 1.0f);
  CHECK(wf[1] == 0.0f);
  // A point on top of its driver: logit 0 exactly, the rest underflow.
  std::vector<Vector3<float>> xg = {Vector3<float>(0, 0, 0), Vector3<float>(30, 0, 0)};
  std::vector<float> sg = {0.1f, 0.1f};
  CHECK_FALSE(smg::skinning_weights_point<float>(pf, 2, xg.data(), sg.data(), wf));
  CHECK(wf[0] == 1.0f);
  CHECK(wf[1] == 0.0f);
}

TEST_CASE("weight Jacobians against central differences and AutoDiffScalar; VJP = Jᵀ g") {
  using smg::test::AD;
  SMG_TEST_RNG(rng, 512);
  for (int trial = 0; trial < 20; ++trial) {
    const int D = rng.integer(1, 9);
    const Case c = random_case(rng, D);
    std::vector<double> w(D), Js(D * D);
    std::vector<Vector3<double>> Jp(D), Jx(D * D);
    smg::skinning_weights_point<double>(c.p, D, c.x.data(), c.sigma.data(), w.data(), Jp.data(),
                                        Jx.data(), Js.data());
    // Dense analytic Jacobian: columns p (3), x_0..x_{D-1} (3 each), sigma (D).
    MatrixXd J(D, 3 + 4 * D);
    for (int j = 0; j < D; ++j) {
      J.block(j, 0, 1, 3) = Jp[j].transpose();
      for (int k = 0; k < D; ++k) {
        J.block(j, 3 + 3 * k, 1, 3) = Jx[j * D + k].transpose();
        J(j, 3 + 3 * D + k) = Js[j * D + k];
      }
    }
    VectorXd v0(3 + 4 * D);
    v0.head<3>() = c.p;
    for (int k = 0; k < D; ++k) {
      v0.segment<3>(3 + 3 * k) = c.x[k];
      v0(3 + 3 * D + k) = c.sigma[k];
    }
    auto unpack = [&](const VectorXd& v) {
      Case e = c;
      e.p = v.head<3>();
      for (int k = 0; k < D; ++k) {
        e.x[k] = v.segment<3>(3 + 3 * k);
        e.sigma[k] = v(3 + 3 * D + k);
      }
      return e;
    };
    CHECK(relative_error(J, central_jacobian([&](const VectorXd& v) { return weights(unpack(v)); },
                                             v0)) < 1e-8);
    // AutoDiffScalar.
    const Index n = v0.size();
    std::vector<Vector3<AD>> xa(D);
    std::vector<AD> sa(D), wa(D);
    Vector3<AD> pa;
    for (int i = 0; i < 3; ++i) pa(i) = AD(c.p(i), n, i);
    for (int k = 0; k < D; ++k) {
      for (int i = 0; i < 3; ++i) xa[k](i) = AD(c.x[k](i), n, 3 + 3 * k + i);
      sa[k] = AD(c.sigma[k], n, 3 + 3 * D + k);
    }
    smg::skinning_weights_point<AD>(pa, D, xa.data(), sa.data(), wa.data());
    MatrixXd Jad(D, n);
    for (int j = 0; j < D; ++j) Jad.row(j) = wa[j].derivatives().transpose();
    CHECK(relative_error(J, Jad) < 1e-13);
    // VJP.
    VectorXd g(D);
    for (int k = 0; k < D; ++k) g(k) = rng.normal();
    Vector3<double> gp = Vector3<double>::Zero();
    std::vector<Vector3<double>> gx(D);
    std::vector<double> gs(D);
    smg::skinning_weights_point_vjp<double>(c.p, D, c.x.data(), c.sigma.data(), w.data(), g.data(),
                                            &gp, gx.data(), gs.data());
    VectorXd v(n);
    v.head<3>() = gp;
    for (int k = 0; k < D; ++k) {
      v.segment<3>(3 + 3 * k) = gx[k];
      v(3 + 3 * D + k) = gs[k];
    }
    CHECK(relative_error(v, J.transpose() * g) < 1e-13);
  }
}

TEST_CASE("weights: float against double") {
  SMG_TEST_RNG(rng, 513);
  double worst = 0, worst_j = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const int D = rng.integer(1, 17);
    const Case c = random_case(rng, D, 3.0);
    std::vector<double> w(D), Js(D * D);
    std::vector<Vector3<double>> Jp(D);
    smg::skinning_weights_point<double>(c.p, D, c.x.data(), c.sigma.data(), w.data(), Jp.data(),
                                        nullptr, Js.data());
    std::vector<Vector3<float>> xf;
    std::vector<float> sf, wf(D), Jsf(D * D);
    std::vector<Vector3<float>> Jpf(D);
    for (int k = 0; k < D; ++k) {
      xf.push_back(c.x[k].cast<float>());
      sf.push_back(float(c.sigma[k]));
    }
    smg::skinning_weights_point<float>(c.p.cast<float>(), D, xf.data(), sf.data(), wf.data(),
                                       Jpf.data(), nullptr, Jsf.data());
    for (int k = 0; k < D; ++k) worst = std::max(worst, std::abs(double(wf[k]) - w[k]));
    for (int k = 0; k < D; ++k)
      worst_j = std::max(worst_j, relative_error(Jpf[k], Jp[k], 1.0));
  }
  MESSAGE("float vs double: weights (absolute) ", worst, ", dw/dp (relative, floor 1) ", worst_j);
  CHECK(worst < 1e-5);
  CHECK(worst_j < 1e-4);
}
