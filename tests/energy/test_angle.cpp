// Term-specific tests of the rotation-angle velocity / acceleration (E23, smg/energy/angle.hpp,
// docs/math/terms/angle.md). The operator list (tests/support/operators.hpp) gives the generic
// ones (central differences, AutoDiffScalar, float against double, threads, hard cases, the fused
// step); here: exact values on constructed rotations, the zero sub-gradient, the sign of q, half
// turns, the raw-quaternion gradient and the normalisation.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"
#include "smg/energy.hpp"
#include "support/random.hpp"

namespace {

// Rotations [T][N][4] of N nodes, node i at frame t: base_i ⊗ Exp(t·angles[t-prefix sum]·axis_i),
// i.e. a rotation by step(t) about a fixed axis between frames t and t + 1.
struct AngleScene {
  smg::Index T, N;
  std::vector<double> q;
  smg::QuaternionsView<const double> view() const { return {q.data(), T, N}; }
};

AngleScene angle_scene(smg::Index T, smg::Index N, const std::vector<double>& steps, unsigned seed,
                       double scale = 1.0) {
  SMG_TEST_RNG(rng, seed);
  AngleScene s{T, N, std::vector<double>(static_cast<std::size_t>(4 * T * N))};
  for (smg::Index i = 0; i < N; ++i) {
    const smg::Quaternion<double> base = rng.quaternion();
    const Eigen::Vector3d axis = rng.unit3();
    double acc = 0;
    for (smg::Index t = 0; t < T; ++t) {
      const smg::Quaternion<double> r = base * smg::so3::exp(Eigen::Vector3d(acc * axis));
      const Eigen::Vector4d w = smg::to_wxyz(r) * scale;
      for (int k = 0; k < 4; ++k) s.q[static_cast<std::size_t>(4 * (t * N + i) + k)] = w(k);
      if (t + 1 < T) acc += steps[static_cast<std::size_t>(t)];
    }
  }
  return s;
}

smg::AngleOptions angle_options(smg::AccelForm form, smg::Normalization n = smg::Normalization::sum) {
  smg::AngleOptions o;
  o.form = form;
  o.normalization = n;
  return o;
}

// Random rotations [T][N][4] as raw quaternions of norms in [0.5, 2] (the operators normalise).
std::vector<double> raw_quaternions(smg::Index T, smg::Index N, smg::test::Rng& rng) {
  std::vector<double> q(static_cast<std::size_t>(4 * T * N));
  for (smg::Index k = 0; k < T * N; ++k) {
    const Eigen::Vector4d w = smg::to_wxyz(rng.quaternion()) * rng.uniform(0.5, 2.0);
    for (int c = 0; c < 4; ++c) q[static_cast<std::size_t>(4 * k + c)] = w(c);
  }
  return q;
}

}  // namespace

TEST_CASE("angle: constant rotations give energy 0 and a gradient exactly 0") {
  const AngleScene s = angle_scene(7, 5, std::vector<double>(6, 0.0), 4401, 1.7);
  for (smg::AccelForm form : smg::kAccelForms) {
    CAPTURE(smg::to_string(form));
    std::vector<double> gr(static_cast<std::size_t>(3 * s.T * s.N), 0.0);
    const double e = smg::angle<double>(s.view(), {}, angle_options(form), smg::TangentsView<double>(gr.data(), s.T, s.N));
    CHECK(e == 0.0);
    for (double g : gr) CHECK(g == 0.0);
  }
}

TEST_CASE("angle: a rotation by a known angle per frame gives θ exactly") {
  const std::vector<double> steps = {0.3, 0.5, 0.45, 2.9, 0.1, 1.0};
  const smg::Index T = 7, N = 4;
  const AngleScene s = angle_scene(T, N, steps, 4402);
  double vel = 0, acc = 0;
  for (std::size_t t = 0; t < steps.size(); ++t) vel += steps[t];
  for (std::size_t t = 0; t + 1 < steps.size(); ++t) acc += std::abs(steps[t + 1] - steps[t]);
  const double ev = smg::angle<double>(s.view(), {}, angle_options(smg::AccelForm::velocity), smg::TangentsView<double>());
  const double ea = smg::angle<double>(s.view(), {}, angle_options(smg::AccelForm::acceleration), smg::TangentsView<double>());
  CHECK(ev == doctest::Approx(N * vel).epsilon(1e-13));
  CHECK(ea == doctest::Approx(N * acc).epsilon(1e-13));
  // Mean: over (T − 1)·N and (T − 2)·N terms; the weight scales.
  smg::AngleOptions o = angle_options(smg::AccelForm::velocity, smg::Normalization::mean);
  o.weight = 2.5;
  CHECK(smg::angle<double>(s.view(), {}, o, smg::TangentsView<double>()) ==
        doctest::Approx(2.5 * vel / (T - 1)).epsilon(1e-13));
  o.form = smg::AccelForm::acceleration;
  CHECK(smg::angle<double>(s.view(), {}, o, smg::TangentsView<double>()) ==
        doctest::Approx(2.5 * acc / (T - 2)).epsilon(1e-13));
  // The velocity gradient: −u on frame t, +u on t + 1 (u the unit axis in the body frame of t).
  std::vector<double> gr(static_cast<std::size_t>(3 * T * N), 0.0);
  smg::angle<double>(s.view(), {}, angle_options(smg::AccelForm::velocity), smg::TangentsView<double>(gr.data(), T, N));
  for (smg::Index i = 0; i < N; ++i) {
    CHECK(Eigen::Map<const Eigen::Vector3d>(&gr[static_cast<std::size_t>(3 * i)]).norm() == doctest::Approx(1.0));
    for (smg::Index t = 1; t + 1 < T; ++t)  // u is the same axis at every frame: −u + u = 0
      CHECK(Eigen::Map<const Eigen::Vector3d>(&gr[static_cast<std::size_t>(3 * (t * N + i))]).norm() < 1e-12);
  }
}

TEST_CASE("angle: q and −q give the same energy and the same tangent gradient") {
  SMG_TEST_RNG(rng, 4403);
  const smg::Index T = 9, N = 6;
  std::vector<double> q = raw_quaternions(T, N, rng);
  std::vector<double> flipped = q;
  for (std::size_t k = 0; k < flipped.size(); k += 8)  // every other quaternion negated
    for (int c = 0; c < 4; ++c) flipped[k + c] = -flipped[k + c];
  for (smg::AccelForm form : smg::kAccelForms) {
    CAPTURE(smg::to_string(form));
    std::vector<double> g0(static_cast<std::size_t>(3 * T * N), 0.0), g1 = g0;
    const double e0 = smg::angle<double>({q.data(), T, N}, {}, angle_options(form), smg::TangentsView<double>(g0.data(), T, N));
    const double e1 = smg::angle<double>({flipped.data(), T, N}, {}, angle_options(form), smg::TangentsView<double>(g1.data(), T, N));
    CHECK(e0 > 0);
    CHECK(e1 == doctest::Approx(e0).epsilon(1e-14));
    for (std::size_t k = 0; k < g0.size(); ++k) CHECK(g1[k] == doctest::Approx(g0[k]).epsilon(1e-12).scale(1.0));
  }
}

TEST_CASE("angle: relative rotations near and at 180 degrees stay finite") {
  for (double a : {M_PI - 1e-9, M_PI - 1e-4, M_PI, 3.0}) {
    CAPTURE(a);
    const AngleScene s = angle_scene(5, 3, {a, a * 0.5, a, a}, 4404);
    for (smg::AccelForm form : smg::kAccelForms) {
      std::vector<double> gr(static_cast<std::size_t>(4 * s.T * s.N), 0.0);
      const double e = smg::angle<double>(s.view(), {}, angle_options(form), smg::QuaternionsView<double>(gr.data(), s.T, s.N));
      CHECK(std::isfinite(e));
      for (double g : gr) CHECK(std::isfinite(g));
    }
    // θ stays in [0, π]: the velocity energy of one step a ≤ π is a itself.
    const AngleScene one = angle_scene(2, 1, {a}, 4405);
    CHECK(smg::angle<double>(one.view(), {}, angle_options(smg::AccelForm::velocity), smg::TangentsView<double>()) ==
          doctest::Approx(a).epsilon(1e-7));
  }
}

TEST_CASE("angle: the raw-quaternion gradient matches central differences on the raw coordinates") {
  SMG_TEST_RNG(rng, 4406);
  const smg::Index T = 6, N = 3;
  std::vector<double> q = raw_quaternions(T, N, rng);
  std::vector<double> conf(static_cast<std::size_t>(T * N));
  for (double& c : conf) c = rng.uniform(0.2, 1.0);
  for (smg::AccelForm form : smg::kAccelForms) {
    CAPTURE(smg::to_string(form));
    smg::AngleOptions o = angle_options(form, smg::Normalization::mean);
    o.confidence_weighted = true;
    std::vector<double> g(q.size(), 0.0);
    const smg::FrameScalarsView<const double> cv(conf.data(), T, N);
    smg::angle<double>({q.data(), T, N}, cv, o, smg::QuaternionsView<double>(g.data(), T, N));
    const double h = 1e-6;
    for (std::size_t k = 0; k < q.size(); ++k) {
      std::vector<double> qp = q, qm = q;
      qp[k] += h;
      qm[k] -= h;
      const double fd = (smg::angle<double>({qp.data(), T, N}, cv, o, smg::TangentsView<double>()) -
                         smg::angle<double>({qm.data(), T, N}, cv, o, smg::TangentsView<double>())) /
                        (2 * h);
      CHECK(g[k] == doctest::Approx(fd).epsilon(1e-6).scale(1.0));
    }
  }
}

TEST_CASE("angle: the fused step gives the separate operator's energy and rotation gradient") {
  const AngleScene s = angle_scene(11, 4, {0.1, 0.4, 0.2, 0.8, 0.3, 0.3, 1.2, 0.05, 0.6, 0.9}, 4407);
  std::vector<double> x(static_cast<std::size_t>(3 * s.T * s.N), 0.0);
  std::vector<std::int32_t> idx(static_cast<std::size_t>(s.N), -1);
  std::vector<double> w(static_cast<std::size_t>(s.N), 0.0);
  smg::RegularizerOptions o;
  smg::for_each_term(o, [](const char*, bool& on, const auto&) { on = false; });
  o.terms.angle = true;
  o.angle.form = smg::AccelForm::velocity;
  std::vector<double> g0(static_cast<std::size_t>(3 * s.T * s.N), 0.0), g1 = g0;
  const smg::RegularizerResult<double> r = smg::regularizers<double>(
      {x.data(), s.T, s.N}, s.view(), {}, smg::NeighborsView<double>(idx.data(), w.data(), s.N, 1), o, {}, {},
      smg::TangentsView<double>(g0.data(), s.T, s.N));
  const double e = smg::angle<double>(s.view(), {}, o.angle, smg::TangentsView<double>(g1.data(), s.T, s.N));
  CHECK(r.angle == e);
  CHECK(r.total() == e);
  CHECK(g0 == g1);
  // Without rotations the fused step refuses the term, naming them.
  const smg::Status st = smg::validate_regularizers<double>(
      {x.data(), s.T, s.N}, smg::QuaternionsView<const double>(), {},
      smg::NeighborsView<double>(idx.data(), w.data(), s.N, 1), o);
  CHECK(!st);
  CHECK(std::string(st.message()).rfind("rotations", 0) == 0);
}
