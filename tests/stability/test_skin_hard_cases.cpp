// Hard cases of smg/skin: nearly antipodal rotations (179.9°, 180°, 180.1°), the pivot switch,
// the |b_r| >= max w bound, a node without neighbours, huge and tiny coordinates, zero weights,
// far points whose weights underflow, and NaN/Inf inputs rejected by validation.
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "skin/skin_test_support.hpp"
#include "support/prelude.hpp"

using smg::SkinMethod;
using smg::test::Drivers;

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr SkinMethod kMethods[] = {SkinMethod::dqb, SkinMethod::lbs};

// Two drivers at x0, x1 (static positions); driver 1 rotates by `angle` about `axis` (about its
// own position), driver 0 stays. Weights (1 − w, w).
Drivers pair(double angle, const Vector3<double>& axis, double w, bool negate0, bool negate1) {
  Drivers d(2);
  d[0].x_ref = d[0].x_t = Vector3<double>(-1, 0.2, 0);
  d[1].x_ref = d[1].x_t = Vector3<double>(1, -0.1, 0.3);
  d[1].q_t = smg::so3::exp(Vector3<double>(angle * axis));
  if (negate0) d[0].q_t.coeffs() = -d[0].q_t.coeffs();
  if (negate1) d[1].q_t.coeffs() = -d[1].q_t.coeffs();
  d[0].weight = 1 - w;
  d[1].weight = w;
  return d;
}
}  // namespace

TEST_CASE("blends of rotations 179.9 degrees apart stay finite and continuous") {
  SMG_TEST_RNG(rng, 531);
  const Vector3<double> p(0.1, 0.4, -0.2);
  const Quaternion<double> qp = rng.quaternion();
  for (double degrees : {179.9, 180.0, 180.1}) {
    CAPTURE(degrees);
    const double angle = degrees * kPi / 180;
    const Vector3<double> axis = rng.unit3();
    for (int signs = 0; signs < 4; ++signs) {
      CAPTURE(signs);
      for (SkinMethod m : kMethods) {
        const int steps = 2000;
        Vector3<double> prev_p = Vector3<double>::Zero();
        Quaternion<double> prev_q = Quaternion<double>::Identity();
        double max_step_q = 0, max_step_p = 0, max_jac = 0;
        for (int i = 0; i <= steps; ++i) {
          const double w = double(i) / steps;
          const Drivers d = pair(angle, axis, w, signs & 1, signs & 2);
          Vector3<double> po;
          Quaternion<double> qo;
          smg::SkinDriverJacobian<double> J[2];
          smg::SkinPointJacobian<double> Jp;
          smg::skin_point(m, d.data(), 2, p, qp, &po, &qo, J, &Jp);
          REQUIRE(po.allFinite());
          REQUIRE(qo.coeffs().allFinite());
          REQUIRE((J[0].allFinite() && J[1].allFinite() && Jp.allFinite()));
          max_jac = std::max({max_jac, J[0].norm(), J[1].norm()});
          if (i > 0) {
            max_step_q = std::max(max_step_q, smg::so3::angular_distance(qo, prev_q));
            max_step_p = std::max(max_step_p, (po - prev_p).norm());
          }
          prev_p = po;
          prev_q = qo;
        }
        // Per step of 1/2000 in w the blended angle moves at most max|dθ/dw|/2000, with
        // dθ/dw = 2 sin α / |b_r|² <= 2 / ((1 − w)² + w²) <= 4 rad (docs/math/skin.md,
        // "Antipodal blends").
        CHECK(max_step_q < 4.0 / steps * 1.01);
        CHECK(max_step_p < 0.02);
        CHECK(max_jac < 100);
      }
    }
  }
}

TEST_CASE("pivot switch at equal weights is continuous; exactly 180 degrees picks + (tie rule)") {
  const Vector3<double> axis = Vector3<double>(0.3, -0.5, 0.8).normalized();
  const Vector3<double> p(0.3, 0.1, 0.2);
  for (double degrees : {179.9, 180.1, 200.0, 300.0}) {
    const double angle = degrees * kPi / 180;
    const double eps = 1e-12;
    Vector3<double> pa, pb;
    Quaternion<double> qa, qb;
    const Drivers a = pair(angle, axis, 0.5 - eps, false, false);
    const Drivers b = pair(angle, axis, 0.5 + eps, false, false);
    smg::skin_point(SkinMethod::dqb, a.data(), 2, p, Quaternion<double>::Identity(), &pa, &qa);
    smg::skin_point(SkinMethod::dqb, b.data(), 2, p, Quaternion<double>::Identity(), &pb, &qb);
    CHECK((pa - pb).norm() < 1e-10);
    CHECK(smg::so3::angular_distance(qa, qb) < 1e-10);
  }
  // Exactly antipodal motion quaternions (a 360° turn is the identity with q = −1): the dot
  // is -1, the blend picks the aligned sign and gives the identity, not a 0/0.
  Drivers d = pair(2 * kPi, axis, 0.5, false, false);
  Vector3<double> po;
  Quaternion<double> qo;
  smg::skin_point(SkinMethod::dqb, d.data(), 2, p, Quaternion<double>::Identity(), &po, &qo);
  CHECK((po - p).norm() < 1e-14);
  CHECK(smg::so3::angular_distance(qo, Quaternion<double>::Identity()) < 1e-14);
}

TEST_CASE("the blend's real part never vanishes: |b_r| >= max weight (sign alignment)") {
  SMG_TEST_RNG(rng, 532);
  for (int trial = 0; trial < 2000; ++trial) {
    const int D = rng.integer(1, 17);
    Drivers d = smg::test::random_drivers(rng, D);
    double wmax = 0;
    for (auto& x : d) {
      x.weight = rng.uniform(0, 1) < 0.3 ? 0.0 : rng.uniform(0, 1);
      wmax = std::max(wmax, x.weight);
    }
    if (wmax == 0) d[0].weight = wmax = 0.5;
    smg::detail::SkinBlendState<double> st;
    smg::detail::skin_blend_forward<double>(SkinMethod::dqb, d.data(), D, Vector3<double>::Zero(),
                                    Quaternion<double>::Identity(), st);
    CHECK(1 / st.inv_norm >= wmax * (1 - 1e-15));
  }
}

TEST_CASE("a node without neighbours drives its points alone; zero-weight drivers add nothing") {
  SMG_TEST_RNG(rng, 533);
  smg::test::SkinScene s = smg::test::random_scene(rng, 2, 6, 3, 12);
  for (auto& v : s.graph_idx) v = -1;  // every node isolated
  for (auto& v : s.graph_w) v = 0;
  const Index D = 4;
  std::vector<std::int32_t> drivers(s.P * D);
  smg::skin_drivers(smg::NeighborsView<double>(s.graph_idx.data(), s.graph_w.data(), s.N, s.K),
                    {s.anchor.data(), s.P}, {drivers.data(), s.P, D});
  std::vector<double> w(s.P * D);
  smg::skinning_weights<double>({s.positions.data(), s.T, s.N}, {drivers.data(), s.P, D},
                                {s.t_ref.data(), s.P}, {s.points.data(), s.P}, {s.sigma.data(), s.N},
                                {w.data(), s.P, D});
  for (Index p = 0; p < s.P; ++p) {
    CHECK(drivers[p * D] == s.anchor[p]);
    CHECK(drivers[p * D + 1] == -1);
    CHECK(w[p * D] == 1.0);
  }
  // One point, a driver with weight 0 next to the anchor: same output as the anchor alone.
  Drivers d = smg::test::random_drivers(rng, 3);
  d[1].weight = 0;
  d[2].weight = 0;
  const Vector3<double> p = rng.vec3();
  for (SkinMethod m : kMethods) {
    Vector3<double> p3, p1;
    Quaternion<double> q3, q1;
    smg::skin_point(m, d.data(), 3, p, Quaternion<double>::Identity(), &p3, &q3);
    smg::skin_point(m, d.data(), 1, p, Quaternion<double>::Identity(), &p1, &q1);
    CHECK((p3 - p1).norm() < 1e-14);
    CHECK(smg::so3::angular_distance(q3, q1) < 1e-15);
  }
}

TEST_CASE("huge and tiny coordinates: relative accuracy and translation covariance") {
  SMG_TEST_RNG(rng, 534);
  for (double scale : {1e-6, 1.0, 1e6}) {
    CAPTURE(scale);
    for (int trial = 0; trial < 20; ++trial) {
      Drivers d = smg::test::random_drivers(rng, 5);
      for (auto& x : d) {
        x.x_ref *= scale;
        x.x_t *= scale;
      }
      const Vector3<double> p = rng.vec3(scale);
      const Quaternion<double> qp = rng.quaternion();
      Vector3<double> po, pr;
      Quaternion<double> qo, qr;
      smg::skin_point(SkinMethod::dqb, d.data(), 5, p, qp, &po, &qo);
      smg::test::reference_dqb(d, p, qp, &pr, &qr);
      CHECK((po - pr).norm() < 1e-13 * scale);
      // Shift everything by c: the output shifts by c, the rotation is unchanged.
      const Vector3<double> c = rng.vec3(1e3 * scale);
      Drivers e = d;
      for (auto& x : e) {
        x.x_ref += c;
        x.x_t += c;
      }
      Vector3<double> ps;
      Quaternion<double> qs;
      smg::skin_point(SkinMethod::dqb, e.data(), 5, Vector3<double>(p + c), qp, &ps, &qs);
      CHECK((ps - c - po).norm() < 1e-11 * scale);
      CHECK(smg::so3::angular_distance(qs, qo) < 1e-13);
      // Float keeps its relative accuracy at any scale.
      std::vector<smg::SkinDriver<float>> f(5);
      for (int k = 0; k < 5; ++k) {
        f[k].x_ref = d[k].x_ref.cast<float>();
        f[k].x_t = d[k].x_t.cast<float>();
        f[k].q_ref = d[k].q_ref.cast<float>();
        f[k].q_t = d[k].q_t.cast<float>();
        f[k].weight = float(d[k].weight);
      }
      Vector3<float> pf;
      smg::skin_point(SkinMethod::dqb, f.data(), 5, Vector3<float>(p.cast<float>()),
                      qp.cast<float>(), &pf, nullptr);
      CHECK((pf.cast<double>() - po).norm() < 1e-5 * scale);
    }
  }
}

TEST_CASE("far points: weights underflow without NaN; the blend stays defined") {
  SMG_TEST_RNG(rng, 535);
  smg::test::SkinScene s = smg::test::random_scene(rng, 2, 8, 3, 20);
  for (auto& x : s.points) x += 1e4;  // thousands of sigmas away from every node
  const Index D = 4;
  std::vector<std::int32_t> drivers(s.P * D);
  smg::skin_drivers(smg::NeighborsView<double>(s.graph_idx.data(), s.graph_w.data(), s.N, s.K),
                    {s.anchor.data(), s.P}, {drivers.data(), s.P, D});
  std::vector<double> w(s.P * D);
  const Index fallbacks = smg::skinning_weights<double>(
      {s.positions.data(), s.T, s.N}, {drivers.data(), s.P, D}, {s.t_ref.data(), s.P},
      {s.points.data(), s.P}, {s.sigma.data(), s.N}, {w.data(), s.P, D});
  CHECK(fallbacks == 0);  // the softmax needs no fallback here: exp(l − max) never underflows all
  for (Index p = 0; p < s.P; ++p) {
    double sum = 0;
    for (Index k = 0; k < D; ++k) {
      CHECK(std::isfinite(w[p * D + k]));
      sum += w[p * D + k];
    }
    CHECK(std::abs(sum - 1) < 1e-15);
  }
  std::vector<std::int32_t> tq = {1};
  std::vector<double> out(s.P * 3);
  smg::SkinPoints<double> pts;
  pts.drivers = {drivers.data(), s.P, D};
  pts.weights = {w.data(), s.P, D};
  pts.t_ref = {s.t_ref.data(), s.P};
  pts.positions = {s.points.data(), s.P};
  smg::SkinBlendOutputs<double> o;
  o.positions = {out.data(), 1, s.P};
  const smg::SkinNodes<double> nodes{{s.positions.data(), s.T, s.N}, {s.quats.data(), s.T, s.N}};
  REQUIRE(smg::validate_skin_blend(nodes, pts, {tq.data(), 1}, o).is_ok());
  smg::skin_blend(nodes, pts, {tq.data(), 1}, o);
  for (double v : out) CHECK(std::isfinite(v));
}

TEST_CASE("NaN and Inf inputs are rejected by validation, naming the argument") {
  SMG_TEST_RNG(rng, 536);
  smg::test::SkinScene s = smg::test::random_scene(rng, 2, 5, 2, 4);
  const Index D = 3;
  std::vector<std::int32_t> drivers(s.P * D);
  smg::skin_drivers(smg::NeighborsView<double>(s.graph_idx.data(), s.graph_w.data(), s.N, s.K),
                    {s.anchor.data(), s.P}, {drivers.data(), s.P, D});
  std::vector<double> w(s.P * D);
  const double inf = std::numeric_limits<double>::infinity();
  auto weights_msg = [&](const smg::test::SkinScene& v) {
    return smg::validate_skinning_weights<double>(
               {v.positions.data(), v.T, v.N}, {drivers.data(), v.P, D}, {v.t_ref.data(), v.P},
               {v.points.data(), v.P}, {v.sigma.data(), v.N}, {w.data(), v.P, D})
        .message();
  };
  CHECK(weights_msg(s).empty());
  smg::test::SkinScene v = s;
  v.sigma[1] = inf;
  CHECK(weights_msg(v) == "sigma: element [1] is Inf");
  v = s;
  v.sigma[2] = -1;
  CHECK(weights_msg(v) == "sigma: element [2] = -1 is not positive");
  v = s;
  v.positions[3 * 5 + 1] = -inf;
  CHECK(weights_msg(v) == "positions: element [t=1][i=0] is Inf");
  v = s;
  v.points[2] = std::numeric_limits<double>::quiet_NaN();
  CHECK(weights_msg(v) == "points: element [0][2] is NaN");

  smg::skinning_weights<double>({s.positions.data(), s.T, s.N}, {drivers.data(), s.P, D},
                                {s.t_ref.data(), s.P}, {s.points.data(), s.P},
                                {s.sigma.data(), s.N}, {w.data(), s.P, D});
  std::vector<std::int32_t> tq = {0};
  smg::SkinPoints<double> pts;
  pts.drivers = {drivers.data(), s.P, D};
  pts.weights = {w.data(), s.P, D};
  pts.t_ref = {s.t_ref.data(), s.P};
  pts.positions = {s.points.data(), s.P};
  std::vector<double> q = s.quats;
  q[4 * 3 + 2] = inf;
  const smg::SkinNodes<double> nodes{{s.positions.data(), s.T, s.N}, {q.data(), s.T, s.N}};
  CHECK(smg::validate_skin_blend(nodes, pts, {tq.data(), 1}, smg::SkinBlendOutputs<double>{})
            .message() == "quaternions: element [t=0][i=3] is Inf");
  std::vector<double> wn = w;
  wn[1] = std::numeric_limits<double>::quiet_NaN();
  pts.weights = {wn.data(), s.P, D};
  const smg::SkinNodes<double> good{{s.positions.data(), s.T, s.N}, {s.quats.data(), s.T, s.N}};
  CHECK(smg::validate_skin_blend(good, pts, {tq.data(), 1}, smg::SkinBlendOutputs<double>{})
            .message() == "weights: element [0][1] is NaN");
}
