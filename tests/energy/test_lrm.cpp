// Tests of smg/energy/lrm.hpp: values against the reference, the exact gradient (ω through the
// regularised solve, μ through trace(A)) against central finite differences and
// AutoDiffScalar, the detached-ω variant, determinism, rigid-motion behaviour and invariances.
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

double lrm_energy(const Scene<double>& s, const smg::LrmOptions& o, bool use_conf,
                  std::vector<double>* grad = nullptr, int threads = 1) {
  smg::ParallelOptions par;
  par.threads = threads;
  smg::PositionsView<double> g;
  if (grad) {
    grad->assign(s.x.size(), 0.0);
    g = smg::PositionsView<double>(grad->data(), s.T, s.N);
  }
  return smg::lrm<double>(s.positions(),
                          use_conf ? s.confidence() : smg::FrameScalarsView<const double>(),
                          s.graph(), o, g, nullptr, par);
}

std::vector<double> fd(const Scene<double>& s, const smg::LrmOptions& o, bool use_conf,
                       double h = 1e-6) {
  Scene<double> p = s;
  return smg::test::central_gradient(p.x, [&] { return lrm_energy(p, o, use_conf); }, h);
}

}  // namespace

TEST_CASE("LRM energy matches the reference") {
  SMG_TEST_RNG(rng, 501);
  for (int rep = 0; rep < 3; ++rep) {
    const Scene<double> s = smg::test::random_scene(2 + rep * 3, 10, 6, rng);
    smg::LrmOptions o;
    o.huber_delta = 0.03;
    for (bool use_conf : {true, false})
      for (bool detach : {false, true}) {
        o.detach_omega = detach;
        const auto X = smg::test::ref::positions_of<double>(s);
        const double ref = smg::test::ref::lrm<double>(s, X, use_conf ? &s.c : nullptr, o, 1e-10);
        const double e = lrm_energy(s, o, use_conf);
        CHECK(std::abs(e - ref) <= 1e-12 * std::abs(ref));
      }
  }
}

TEST_CASE("LRM gradient matches central finite differences") {
  SMG_TEST_RNG(rng, 502);
  for (int rep = 0; rep < 3; ++rep) {
    const Scene<double> s = smg::test::random_scene(2 + rep * 2, 9, 5, rng);
    for (double delta : {0.01, 0.05, 10.0})
      for (bool detach : {false, true}) {
        const smg::LrmOptions o = smg::test::lrm_options(delta, detach);
        CAPTURE(delta);
        CAPTURE(detach);
        std::vector<double> g;
        lrm_energy(s, o, true, &g);
        if (detach) {
          // Finite differences cannot hold ω fixed; the detached gradient is checked against
          // AutoDiffScalar through the reference with ω's derivatives dropped (below).
          continue;
        }
        CHECK(smg::test::relative_error(g, fd(s, o, true)) < 1e-7);
      }
  }
}

TEST_CASE("LRM with omega held constant equals autodiff of the reference with omega detached") {
  SMG_TEST_RNG(rng, 503);
  // At least 3 neighbours: with 2 (collinear x̃) the component of ω along the line is set by
  // μ and rounding, and a gradient that holds ω constant depends on it (the exact one does
  // not) — see docs/math/energy.md.
  Scene<double> s = smg::test::random_scene(4, 8, 5, rng);
  smg::test::random_graph(s, 5, 3, rng);
  using smg::test::AD;
  const Index n = static_cast<Index>(s.x.size());
  std::vector<Vector3<AD>> X(static_cast<std::size_t>(s.T * s.N));
  for (Index k = 0; k < s.T * s.N; ++k)
    for (int c = 0; c < 3; ++c) X[k](c) = AD(s.x[3 * k + c], n, 3 * k + c);
  for (bool detach : {true, false}) {
    const smg::LrmOptions o = smg::test::lrm_options(0.02, detach);
    CAPTURE(detach);
    const AD e = smg::test::ref::lrm<AD>(s, X, &s.c, o, 1e-10);
    std::vector<double> g;
    const double v = lrm_energy(s, o, true, &g);
    CHECK(std::abs(e.value() - v) <= 1e-12 * v);
    std::vector<double> ad(e.derivatives().data(), e.derivatives().data() + n);
    CHECK(smg::test::relative_error(g, ad) < 1e-10);
  }
}

TEST_CASE("LRM is bit-identical for 1, 2 and 7 threads") {
  SMG_TEST_RNG(rng, 504);
  const Scene<double> s = smg::test::random_scene(13, 150, 7, rng);
  smg::LrmOptions o;
  std::vector<double> a, b, c;
  const double ea = lrm_energy(s, o, true, &a, 1), eb = lrm_energy(s, o, true, &b, 2),
               ec = lrm_energy(s, o, true, &c, 7);
  CHECK(ea == eb);
  CHECK(ea == ec);
  CHECK(a == b);
  CHECK(a == c);
}

TEST_CASE("LRM is zero for a rigidly translating scene") {
  SMG_TEST_RNG(rng, 505);
  const Scene<double> s =
      smg::test::rigid_scene(6, 60, 8, 0.0, Vector3<double>(0.02, -0.03, 0.01), rng);
  std::vector<double> g;
  const double e = lrm_energy(s, {}, false, &g);
  CHECK(e < 1e-28);
  for (double v : g) CHECK(std::abs(v) < 1e-14);
}

TEST_CASE("LRM of a rigid rotation: residual O(theta^2), energy O(theta^4), omega to O(theta^2)") {
  // Frame differences of a rotation by θ per frame are (Exp(θ) − I) x = θ × x + ½ θ × (θ × x)
  // + ...: the first term is a rigid twist and is fitted exactly; the second is symmetric in x
  // and is what remains, so the residual is O(θ²) and, in Huber's quadratic zone, the energy
  // ½ r² is O(θ⁴). The fitted ω equals the per-frame angular velocity up to O(θ²).
  SMG_TEST_RNG(rng, 506);
  const Vector3<double> axis = Vector3<double>(0.3, -0.5, 0.8).normalized();
  double prev_r = 0, prev_e = 0, prev_w = 0;
  for (double theta : {0.08, 0.04, 0.02, 0.01}) {
    Rng r2(507);
    const Scene<double> s = smg::test::rigid_scene(4, 80, 10, theta, Vector3<double>::Zero(), r2, axis);
    smg::LrmOptions o;
    o.huber_delta = 1.0;  // quadratic zone
    std::vector<double> om(s.x.size());
    smg::ParallelOptions par;
    const double e = smg::lrm<double>(s.positions(), {}, s.graph(), o, {}, nullptr, par,
                                      {om.data(), s.T, s.N});
    double max_r = 0;
    for (Index t = 0; t < s.T; ++t)
      for (Index i = 0; i < s.N; ++i) {
        smg::LrmResidualBlock<double> b;
        smg::lrm_residual_block<double>(s.positions(), {}, s.graph(), o, t, i, b, false);
        max_r = std::max(max_r, b.raw.cwiseAbs().maxCoeff());
      }
    double max_w = 0;
    for (std::size_t k = 0; k < om.size(); k += 3)
      max_w = std::max(max_w, (Vector3<double>(om[k], om[k + 1], om[k + 2]) - theta * axis).norm());
    CAPTURE(theta);
    CAPTURE(max_r);
    CAPTURE(e);
    CAPTURE(max_w);
    CHECK(max_r < 0.5 * theta * theta);
    CHECK(max_w < 0.5 * theta * theta);
    if (prev_r > 0) {
      CHECK(max_r / prev_r == doctest::Approx(0.25).epsilon(0.1));
      CHECK(e / prev_e == doctest::Approx(1.0 / 16).epsilon(0.1));
      CHECK(max_w / prev_w < 0.3);
    }
    prev_r = max_r;
    prev_e = e;
    prev_w = max_w;
  }
}

TEST_CASE("LRM and its gradient are invariant to a global rigid transform") {
  SMG_TEST_RNG(rng, 508);
  const Scene<double> s = smg::test::random_scene(7, 25, 6, rng);
  const smg::Quaternion<double> Q = rng.quaternion();
  const Scene<double> m = smg::test::transformed(s, Q, rng.vec3(20.0));
  smg::LrmOptions o;
  std::vector<double> a, b;
  const double ea = lrm_energy(s, o, true, &a), eb = lrm_energy(m, o, true, &b);
  CHECK(std::abs(ea - eb) <= 1e-11 * ea);
  std::vector<double> rotated(a.size());
  for (std::size_t k = 0; k < a.size(); k += 3) {
    const Vector3<double> g = Q * Vector3<double>(a[k], a[k + 1], a[k + 2]);
    for (int c = 0; c < 3; ++c) rotated[k + c] = g(c);
  }
  CHECK(smg::test::relative_error(b, rotated) < 1e-9);
}

TEST_CASE("LRM: confidences only reweight; all-zero confidences equal all-one (normalised)") {
  SMG_TEST_RNG(rng, 509);
  Scene<double> s = smg::test::random_scene(5, 20, 5, rng);
  smg::LrmOptions o;
  std::vector<double> none, zero;
  const double e1 = lrm_energy(s, o, false, &none);
  std::fill(s.c.begin(), s.c.end(), 0.0);
  const double e0 = lrm_energy(s, o, true, &zero);
  CHECK(e0 == doctest::Approx(e1).epsilon(1e-13));
  CHECK(smg::test::relative_error(zero, none) < 1e-13);
  // alpha = 0 and zero confidences: no weight at all, so every term is 0.
  o.alpha = 0.0;
  CHECK(lrm_energy(s, o, true) == 0.0);
}

TEST_CASE("LRM: detached and exact gradients agree where Huber is quadratic (envelope)") {
  // With ρ = r²/2 everywhere, L_{t,i} is half the fit's own objective, so ∂L/∂ω = −μω ≈ 0 at
  // the fitted ω: holding ω constant changes the gradient only at the regulariser's level.
  SMG_TEST_RNG(rng, 510);
  const Scene<double> s = smg::test::random_scene(6, 30, 6, rng);
  smg::LrmOptions o;
  o.huber_delta = 100.0;
  std::vector<double> exact, detached;
  lrm_energy(s, o, true, &exact);
  o.detach_omega = true;
  lrm_energy(s, o, true, &detached);
  CHECK(smg::test::relative_error(detached, exact) < 1e-8);
  o.huber_delta = 0.01;  // most residuals in the linear zone: the implicit term matters
  lrm_energy(s, o, true, &detached);
  o.detach_omega = false;
  lrm_energy(s, o, true, &exact);
  CHECK(smg::test::relative_error(detached, exact) > 1e-3);
}

TEST_CASE("LRM: float agrees with double; accumulation, normalisation and weight") {
  SMG_TEST_RNG(rng, 511);
  const Scene<double> s = smg::test::random_scene(17, 120, 8, rng, true);
  smg::LrmOptions o;
  std::vector<double> gd;
  const double ed = lrm_energy(s, o, true, &gd);
  const Scene<float> f = s.cast<float>();
  std::vector<float> gf(s.x.size(), 0.f);
  const double ef = smg::lrm<float>(f.positions(), f.confidence(), f.graph(), o, {gf.data(), s.T, s.N});
  CHECK(std::abs(ef - ed) <= 1e-4 * ed);
  CHECK(smg::test::relative_error(std::vector<double>(gf.begin(), gf.end()), gd) < 1e-3);
  // += semantics
  std::vector<double> acc(s.x.size(), 0.5);
  smg::EnergyWorkspace<double> ws;
  for (int rep = 0; rep < 2; ++rep)
    smg::lrm<double>(s.positions(), s.confidence(), s.graph(), o, {acc.data(), s.T, s.N}, &ws);
  for (std::size_t k = 0; k < acc.size(); ++k)
    CHECK(acc[k] == doctest::Approx(0.5 + 2 * gd[k]).epsilon(1e-12));
  smg::LrmOptions m = o;
  m.normalization = smg::Normalization::mean;
  m.weight = 3.0;
  std::vector<double> gm;
  const double em = lrm_energy(s, m, true, &gm);
  const double terms = double(smg::lrm_term_count(s.graph(), s.T));
  CHECK(em == doctest::Approx(3.0 * ed / terms).epsilon(1e-13));
  CHECK(smg::test::relative_error(gm, std::vector<double>(gd.size())) > 0);
  for (std::size_t k = 0; k < gm.size(); ++k)
    CHECK(gm[k] == doctest::Approx(3.0 * gd[k] / terms).epsilon(1e-12).scale(1e-15));
}

TEST_CASE("LRM: validation") {
  Rng rng(512);
  const Scene<double> s = smg::test::random_scene(3, 6, 3, rng);
  smg::LrmOptions o;
  CHECK(smg::validate_lrm<double>(s.positions(), s.confidence(), s.graph(), o).is_ok());
  o.huber_delta = 0.0;
  CHECK(smg::validate_lrm<double>(s.positions(), s.confidence(), s.graph(), o).message() ==
        "LrmOptions.huber_delta must be finite and > 0, got 0");
  std::vector<double> g(s.x.size());
  CHECK(smg::validate_lrm<double>(s.positions(), s.confidence(), s.graph(), {},
                                  {g.data(), s.T + 1, s.N})
            .message() == "grad_positions: expected shape [T=3][N=6][3], got [T=4][N=6][3]");
  Scene<double> bad = s;
  bad.idx[0] = 6;
  CHECK(smg::validate_lrm<double>(s.positions(), s.confidence(), bad.graph(), {}).message() ==
        "graph: entry [i=0][k=0] is out of range: 6");
}
