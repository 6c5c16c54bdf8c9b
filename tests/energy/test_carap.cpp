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
#include "support/finite_diff.hpp"
#include "support/random.hpp"

using smg::Index;
using smg::Quaternion;
using smg::Vector3;
using smg::test::Rng;
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
  g.x.assign(s.x.size(), 0.0);
  g.r.assign(s.x.size(), 0.0);
  Scene<double> p = s;
  for (std::size_t k = 0; k < s.x.size(); ++k) {
    p.x[k] = s.x[k] + h;
    const double ep = energy_only(p, o, use_conf);
    p.x[k] = s.x[k] - h;
    const double em = energy_only(p, o, use_conf);
    p.x[k] = s.x[k];
    g.x[k] = (ep - em) / (2 * h);
  }
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i)
      for (int c = 0; c < 3; ++c) {
        Vector3<double> d = Vector3<double>::Zero();
        d(c) = h;
        p.set_rot(t, i, s.rot(t, i) * smg::so3::exp(d));
        const double ep = energy_only(p, o, use_conf);
        p.set_rot(t, i, s.rot(t, i) * smg::so3::exp(Vector3<double>(-d)));
        const double em = energy_only(p, o, use_conf);
        p.set_rot(t, i, s.rot(t, i));
        g.r[(t * s.N + i) * 3 + c] = (ep - em) / (2 * h);
      }
  return g;
}

double rel(const std::vector<double>& a, const std::vector<double>& b) {
  double num = 0, den = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    num += (a[k] - b[k]) * (a[k] - b[k]);
    den += b[k] * b[k];
  }
  return std::sqrt(num) / std::max(std::sqrt(den), 1e-300);
}

}  // namespace

TEST_CASE("C-ARAP energy matches the term-by-term reference") {
  Rng rng(401);
  CAPTURE(rng.seed);
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
  Rng rng(402);
  CAPTURE(rng.seed);
  for (int rep = 0; rep < 3; ++rep) {
    const Index T = 5 + rep * 6;  // 5, 11, 17
    const Scene<double> s = smg::test::random_scene(T, 7, 4, rng);
    smg::CarapOptions o;
    o.gaps = {{1, 1.0}, {2, 0.5}, {4, 2.0}};
    o.lambda_c = 0.7;
    o.lambda_l = 1.3;
    CAPTURE(T);
    const Grad a = run_carap(s, o, true);
    const Grad f = finite_difference(s, o, true);
    CHECK(rel(a.x, f.x) < 1e-7);
    CHECK(rel(a.r, f.r) < 1e-7);
  }
}
