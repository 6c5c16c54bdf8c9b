// Tests of smg/energy/carap.hpp and arap.hpp: values against the term-by-term reference,
// gradients (positions and right-tangent rotations) against central finite differences and
// AutoDiffScalar, determinism over thread counts, rigid-motion zeros and invariances, float
// against double.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "energy/reference_energies.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

using smg::test::Scene;

namespace {

struct Grad {
  std::vector<double> x, r;
  double energy = 0;
};

Grad run_carap(const Scene<double>& s, const smg::CarapOptions& o, bool use_conf, int threads = 1,
               bool arap = false) {
  Grad g;
  g.x.assign(s.x.size(), 0.0);
  g.r.assign(s.x.size(), 0.0);
  smg::ParallelOptions par;
  par.threads = threads;
  smg::PositionsView<double> gx(g.x.data(), s.T, s.N);
  smg::TangentsView<double> gr(g.r.data(), s.T, s.N);
  if (arap) {
    smg::ArapOptions a;
    a.lambda_c = o.lambda_c;
    a.lambda_l = o.lambda_l;
    a.gaps = o.gaps;
    a.normalization = o.normalization;
    a.weight = o.weight;
    g.energy = smg::arap<double>(s.positions(), s.rotations(), s.graph(), a, gx, gr, nullptr, par);
  } else {
    g.energy = smg::carap<double>(s.positions(), s.rotations(),
                                  use_conf ? s.confidence() : smg::FrameScalarsView<const double>(),
                                  s.graph(), o, gx, gr, nullptr, par);
  }
  return g;
}

double energy_only(const Scene<double>& s, const smg::CarapOptions& o, bool use_conf) {
  return smg::carap<double>(s.positions(), s.rotations(),
                            use_conf ? s.confidence() : smg::FrameScalarsView<const double>(),
                            s.graph(), o);
}

double reference(const Scene<double>& s, const smg::CarapOptions& o, bool use_conf) {
  const auto X = smg::test::ref::positions_of<double>(s);
  const auto R = smg::test::ref::rotations_of<double>(s);
  return smg::test::ref::carap<double>(s, X, R, use_conf ? &s.c : nullptr, o);
}

// Central differences of the energy w.r.t. every position and every right-tangent rotation.
Grad finite_difference(const Scene<double>& s, const smg::CarapOptions& o, bool use_conf,
                       double h = 1e-6) {
  Grad g;
  Scene<double> p = s;
  const auto energy = [&] { return energy_only(p, o, use_conf); };
  g.x = smg::test::central_gradient(p.x, energy, h);
  g.r.assign(s.x.size(), 0.0);
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i)
      for (int c = 0; c < 3; ++c)
        g.r[(t * s.N + i) * 3 + c] = smg::test::central_difference_tangent(
            s.rot(t, i), c, [&](const smg::Quaternion<double>& q) { p.set_rot(t, i, q); }, energy, h);
  return g;
}

// The analytic gradient (with confidences) equals central finite differences.
void check_against_finite_differences(const Scene<double>& s, const smg::CarapOptions& o) {
  const Grad a = run_carap(s, o, true);
  const Grad f = finite_difference(s, o, true);
  CHECK(smg::test::relative_error(a.x, f.x) < 1e-7);
  CHECK(smg::test::relative_error(a.r, f.r) < 1e-7);
}

}  // namespace

TEST_CASE("C-ARAP energy matches the term-by-term reference") {
  SMG_TEST_RNG(rng, 401);
  for (int rep = 0; rep < 4; ++rep) {
    const Index T = 3 + rep * 7;  // 3, 10, 17, 24: blocks of 8 frames, with and without spill
    const Scene<double> s = smg::test::random_scene(T, 9, 5, rng);
    smg::CarapOptions o;
    o.gaps = {{1, 1.0}, {2, 0.5}, {4, 2.0}, {30, 1.0}};
    o.lambda_c = 0.7;
    o.lambda_l = 1.3;
    for (bool use_conf : {true, false}) {
      CAPTURE(T);
      CAPTURE(use_conf);
      const double ref = reference(s, o, use_conf);
      const double e = energy_only(s, o, use_conf);
      CHECK(std::abs(e - ref) <= 1e-12 * std::abs(ref));
      o.normalization = smg::Normalization::mean;
      CHECK(std::abs(energy_only(s, o, use_conf) - reference(s, o, use_conf)) <= 1e-12 * std::abs(ref));
      o.normalization = smg::Normalization::sum;
    }
  }
}

TEST_CASE("C-ARAP gradient matches central finite differences") {
  SMG_TEST_RNG(rng, 402);
  for (int rep = 0; rep < 3; ++rep) {
    const Index T = 5 + rep * 6;  // 5, 11, 17
    const Scene<double> s = smg::test::random_scene(T, 7, 4, rng);
    smg::CarapOptions o;
    o.gaps = {{1, 1.0}, {2, 0.5}, {4, 2.0}};
    o.lambda_c = 0.7;
    o.lambda_l = 1.3;
    CAPTURE(T);
    check_against_finite_differences(s, o);
  }
}

TEST_CASE("C-ARAP is bit-identical for 1, 2 and 7 threads (with spill blocks)") {
  SMG_TEST_RNG(rng, 403);
  const Scene<double> s = smg::test::random_scene(37, 60, 6, rng);  // several short blocks
  smg::CarapOptions o;
  o.gaps = {{1, 1.0}, {3, 0.5}, {11, 1.0}};  // a gap longer than a block
  const Grad a = run_carap(s, o, true, 1);
  for (int threads : {2, 7}) {
    CAPTURE(threads);
    const Grad b = run_carap(s, o, true, threads);
    CHECK(a.energy == b.energy);
    CHECK(a.x == b.x);
    CHECK(a.r == b.r);
  }
  // And the long gap is right.
  CHECK(std::abs(a.energy - reference(s, o, true)) <= 1e-12 * a.energy);
}

TEST_CASE("C-ARAP gradient with long gaps and many blocks matches finite differences") {
  SMG_TEST_RNG(rng, 404);
  const Scene<double> s = smg::test::random_scene(21, 5, 3, rng);
  smg::CarapOptions o;
  o.gaps = {{2, 1.0}, {9, 0.7}, {20, 1.5}};
  check_against_finite_differences(s, o);
}

TEST_CASE("C-ARAP is zero for a rigidly moving scene") {
  SMG_TEST_RNG(rng, 405);
  const Scene<double> s =
      smg::test::rigid_scene(12, 80, 8, 0.1, Vector3<double>(0.03, -0.01, 0.02), rng);
  const Scene<double> noisy = smg::test::random_scene(12, 80, 8, rng, true);
  smg::CarapOptions o;
  const double e = energy_only(s, o, false);
  const double scale = energy_only(noisy, o, false);
  CAPTURE(e);
  CHECK(e <= 1e-26 * std::max(1.0, scale));
  const Grad g = run_carap(s, o, false);
  for (double v : g.x) CHECK(std::abs(v) < 1e-13);
  for (double v : g.r) CHECK(std::abs(v) < 1e-13);
}

TEST_CASE("C-ARAP and its gradients are invariant to a global rigid transform") {
  SMG_TEST_RNG(rng, 406);
  const Scene<double> s = smg::test::random_scene(9, 20, 5, rng);
  const Quaternion<double> Q = rng.quaternion();
  const Scene<double> m = smg::test::transformed(s, Q, rng.vec3(10.0));
  smg::CarapOptions o;
  const Grad a = run_carap(s, o, true), b = run_carap(m, o, true);
  CHECK(std::abs(a.energy - b.energy) <= 1e-12 * a.energy);
  // Position gradients rotate with the world; right-tangent rotation gradients do not change.
  std::vector<double> rotated(a.x.size());
  for (std::size_t k = 0; k < a.x.size(); k += 3) {
    const Vector3<double> g = Q * Vector3<double>(a.x[k], a.x[k + 1], a.x[k + 2]);
    rotated[k] = g(0);
    rotated[k + 1] = g(1);
    rotated[k + 2] = g(2);
  }
  CHECK(smg::test::relative_error(b.x, rotated) < 1e-11);
  CHECK(smg::test::relative_error(b.r, a.r) < 1e-11);
}

TEST_CASE("C-ARAP: all-zero confidences fall back to the alpha floor; ARAP is c = 1, alpha = 1") {
  SMG_TEST_RNG(rng, 407);
  Scene<double> s = smg::test::random_scene(7, 15, 5, rng);
  smg::CarapOptions o;
  o.alpha = 0.35;
  const Grad plain = run_carap(s, o, false, 1, true);  // ARAP
  std::fill(s.c.begin(), s.c.end(), 0.0);
  const Grad zero = run_carap(s, o, true);
  CHECK(zero.energy == doctest::Approx(0.35 * plain.energy).epsilon(1e-13));
  for (std::size_t k = 0; k < zero.x.size(); ++k)
    CHECK(zero.x[k] == doctest::Approx(0.35 * plain.x[k]).epsilon(1e-12).scale(1e-12));
  std::fill(s.c.begin(), s.c.end(), 1.0);
  const Grad one = run_carap(s, o, true);
  CHECK(one.energy == doctest::Approx(plain.energy).epsilon(1e-13));
  CHECK(one.energy == doctest::Approx(run_carap(s, o, false).energy).epsilon(1e-13));
}

TEST_CASE("C-ARAP: gradients accumulate into the caller's buffers; workspace reuse; weight") {
  SMG_TEST_RNG(rng, 408);
  const Scene<double> s = smg::test::random_scene(11, 30, 6, rng);
  smg::CarapOptions o;
  const Grad a = run_carap(s, o, true);
  std::vector<double> gx(s.x.size(), 1.0), gr(s.x.size(), -2.0);
  smg::EnergyWorkspace<double> ws;
  for (int rep = 0; rep < 2; ++rep)
    smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o,
                       {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N}, &ws);
  for (std::size_t k = 0; k < gx.size(); ++k) {
    CHECK(gx[k] == doctest::Approx(1.0 + 2 * a.x[k]).epsilon(1e-12));
    CHECK(gr[k] == doctest::Approx(-2.0 + 2 * a.r[k]).epsilon(1e-12));
  }
  CHECK(ws.bytes() > 0);
  smg::CarapOptions w = o;
  w.weight = 2.5;
  const Grad b = run_carap(s, w, true);
  CHECK(b.energy == doctest::Approx(2.5 * a.energy).epsilon(1e-13));
  // Only rotations requested.
  std::vector<double> only(s.x.size(), 0.0);
  smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o, {},
                     {only.data(), s.T, s.N});
  CHECK(only == a.r);
}

TEST_CASE("C-ARAP: float agrees with double") {
  SMG_TEST_RNG(rng, 409);
  const Scene<double> s = smg::test::random_scene(20, 200, 8, rng, true);
  smg::CarapOptions o;
  const Grad d = run_carap(s, o, true);
  const Scene<float> f = s.cast<float>();
  std::vector<float> gx(s.x.size(), 0.f), gr(s.x.size(), 0.f);
  const double ef = smg::carap<float>(f.positions(), f.rotations(), f.confidence(), f.graph(), o,
                                      {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N});
  CHECK(std::abs(ef - d.energy) <= 1e-5 * d.energy);
  CHECK(smg::test::relative_error(std::vector<double>(gx.begin(), gx.end()), d.x) < 1e-4);
  CHECK(smg::test::relative_error(std::vector<double>(gr.begin(), gr.end()), d.r) < 1e-4);
}

TEST_CASE("C-ARAP: validation") {
  Rng rng(410);
  const Scene<double> s = smg::test::random_scene(4, 6, 3, rng);
  smg::CarapOptions o;
  CHECK(smg::validate_carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o)
            .is_ok());
  o.gaps = {{0, 1.0}};
  CHECK(smg::validate_carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o)
            .message() == "CarapOptions.gaps[0].delta must be >= 1, got 0");
  o = smg::CarapOptions();
  o.alpha = 1.5;
  CHECK(smg::validate_carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o)
            .message() == "CarapOptions.alpha must be in [0, 1], got 1.5");
  Scene<double> bad = s;
  bad.c[5] = 1.5;
  CHECK(smg::validate_carap<double>(bad.positions(), bad.rotations(), bad.confidence(),
                                    bad.graph(), {})
            .message() == "confidence: element [t=0][i=5] is not in [0, 1]");
  bad = s;
  std::fill(bad.q.begin(), bad.q.begin() + 4, 0.0);
  CHECK(smg::validate_carap<double>(bad.positions(), bad.rotations(), bad.confidence(),
                                    bad.graph(), {})
            .message() == "rotations: element [t=0][i=0] is the zero quaternion");
  std::vector<double> g(3);
  CHECK(!smg::validate_carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), {},
                                     {g.data(), 1, 1})
             .is_ok());
  // ARAP validates its own options.
  smg::ArapOptions a;
  a.lambda_l = -1;
  CHECK(smg::validate_arap<double>(s.positions(), s.rotations(), s.graph(), a).message() ==
        "ArapOptions.lambda_l must be finite and >= 0, got -1");
}
