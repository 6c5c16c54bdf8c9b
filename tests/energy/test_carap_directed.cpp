// The directed reading of C-ARAP (carap_directed.hpp, (E20)): node i's update is the gradient of
// its own terms with the neighbours held fixed. Checked against central finite differences and
// Eigen's AutoDiffScalar of the independent reference energy restricted to node i's terms, its
// rotation part and energy against carap(), and for thread-count independence and hard cases.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "energy/reference_energies.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "smg/energy/carap_directed.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

using smg::test::AD;
using smg::test::Scene;

namespace {

// The scene with every neighbour row but node i's emptied: its C-ARAP energy (Normalization::sum)
// is node i's own terms E_i = Σ_{δ,t,j∈N(i)} E_ij.
Scene<double> only_row(const Scene<double>& s, Index i) {
  Scene<double> r = s;
  for (Index n = 0; n < s.N; ++n)
    if (n != i)
      for (Index k = 0; k < s.K; ++k) r.idx[static_cast<std::size_t>(n * s.K + k)] = -1;
  return r;
}

struct Directed {
  double energy = 0;
  std::vector<double> ux, ur;
};
Directed directed(const Scene<double>& s, const smg::CarapOptions& o, int threads = 0) {
  Directed d;
  d.ux.assign(s.x.size(), 0.0);
  d.ur.assign(s.x.size(), 0.0);
  smg::ParallelOptions par;
  par.threads = threads;
  par.grain = 1;
  d.energy = smg::carap_directed<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o,
                                         {d.ux.data(), s.T, s.N}, {d.ur.data(), s.T, s.N}, par);
  return d;
}

smg::CarapOptions options() {
  smg::CarapOptions o;
  o.gaps = {{1, 1.0}, {2, 0.5}, {4, 0.25}};
  o.alpha = 0.3;
  o.lambda_l = 0.7;
  return o;
}

}  // namespace

TEST_CASE("carap_directed: energy and rotation update equal carap()'s; the position update differs") {
  SMG_TEST_RNG(rng, 811);
  const Scene<double> s = smg::test::random_scene(10, 14, 5, rng);
  const smg::CarapOptions o = options();
  std::vector<double> gx(s.x.size(), 0.0), gr(s.x.size(), 0.0);
  const double e = smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o,
                                      {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N});
  const Directed d = directed(s, o);
  CHECK(d.energy == doctest::Approx(e).epsilon(1e-12));
  CHECK(smg::test::relative_error(d.ur, gr) < 1e-12);
  // Not the gradient: the neighbour ends of the terms are missing.
  CHECK(smg::test::relative_error(d.ux, gx) > 1e-2);
}

TEST_CASE("carap_directed: node i's position update is the derivative of its own terms (FD and AutoDiff)") {
  SMG_TEST_RNG(rng, 812);
  const Scene<double> s = smg::test::random_scene(8, 9, 4, rng);
  const smg::CarapOptions o = options();
  const Directed d = directed(s, o);
  const std::vector<double> conf = s.c;
  for (Index i : {Index(0), Index(4), Index(8)}) {
    CAPTURE(i);
    const Scene<double> si = only_row(s, i);
    // Central differences of the reference energy of node i's terms in x_i^t (double).
    std::vector<double> fd(static_cast<std::size_t>(3 * s.T)), an(fd.size()), ad(fd.size());
    for (Index t = 0; t < s.T; ++t)
      for (int c = 0; c < 3; ++c) {
        Scene<double> p = si;
        double& v = p.x[static_cast<std::size_t>((t * s.N + i) * 3 + c)];
        const auto f = [&] {
          return smg::test::ref::carap<double>(p, smg::test::ref::positions_of<double>(p),
                                               smg::test::ref::rotations_of<double>(p), &conf, o);
        };
        fd[static_cast<std::size_t>(3 * t + c)] = smg::test::central_difference(v, f, 1e-6);
        an[static_cast<std::size_t>(3 * t + c)] = d.ux[static_cast<std::size_t>((t * s.N + i) * 3 + c)];
      }
    // Forward-mode AutoDiff of the same reference, with node i's positions as the variables.
    std::vector<Vector3<AD>> X = smg::test::ref::positions_of<AD>(si);
    for (Index t = 0; t < s.T; ++t)
      for (int c = 0; c < 3; ++c) X[static_cast<std::size_t>(t * s.N + i)](c).derivatives() =
          Eigen::VectorXd::Unit(3 * s.T, 3 * t + c);
    std::vector<smg::Matrix3<AD>> R = smg::test::ref::rotations_of<AD>(si);
    for (auto& m : R)
      for (Index k = 0; k < 9; ++k) m.data()[k].derivatives() = Eigen::VectorXd::Zero(3 * s.T);
    const AD e = smg::test::ref::carap<AD>(si, X, R, &conf, o);
    for (Index k = 0; k < 3 * s.T; ++k) ad[static_cast<std::size_t>(k)] = e.derivatives()(k);
    CHECK(smg::test::relative_error(an, fd) < 1e-7);
    CHECK(smg::test::relative_error(an, ad) < 1e-12);
  }
}

TEST_CASE("carap_directed: the same bits for 1, 2 and 5 threads") {
  Rng rng(813);
  const Scene<double> s = smg::test::random_scene(12, 30, 6, rng);
  const Directed a = directed(s, options(), 1), b = directed(s, options(), 2), c = directed(s, options(), 5);
  CHECK(a.energy == b.energy);
  CHECK(a.energy == c.energy);
  CHECK(a.ux == b.ux);
  CHECK(a.ux == c.ux);
  CHECK(a.ur == c.ur);
}

TEST_CASE("carap_directed: zero-length edges, all confidences zero, no neighbours, float against double") {
  Rng rng(814);
  Scene<double> s = smg::test::random_scene(6, 7, 3, rng);
  // Nodes 0 and its first neighbour coincide at every frame: ‖e‖ = 0 (the pinned derivative).
  const Index j = s.idx[0];
  for (Index t = 0; t < s.T; ++t) s.set_pos(t, j, s.pos(t, 0));
  std::fill(s.c.begin(), s.c.end(), 0.0);  // every w̃ = α w
  // Node 6 has no neighbours: its update is zero unless it is someone's neighbour (it is not used
  // as one on its own side).
  for (Index k = 0; k < s.K; ++k) s.idx[static_cast<std::size_t>(6 * s.K + k)] = -1;
  const Directed d = directed(s, options());
  for (double v : d.ux) CHECK(std::isfinite(v));
  for (Index t = 0; t < s.T; ++t)
    for (int c = 0; c < 3; ++c) {
      CHECK(d.ux[static_cast<std::size_t>((t * s.N + 6) * 3 + c)] == 0.0);
      CHECK(d.ur[static_cast<std::size_t>((t * s.N + 6) * 3 + c)] == 0.0);
    }
  std::vector<double> gx(s.x.size(), 0.0);
  const double e = smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), options(),
                                      {gx.data(), s.T, s.N});
  CHECK(d.energy == doctest::Approx(e).epsilon(1e-12));
  // Float: the same update within float round-off.
  std::vector<float> xf(s.x.begin(), s.x.end()), qf(s.q.begin(), s.q.end()), cf(s.c.begin(), s.c.end()),
      wf(s.w.begin(), s.w.end()), uxf(s.x.size(), 0.0f), urf(s.x.size(), 0.0f);
  const float ef = smg::carap_directed<float>({xf.data(), s.T, s.N}, {qf.data(), s.T, s.N}, {cf.data(), s.T, s.N},
                                              smg::NeighborsView<float>(s.idx.data(), wf.data(), s.N, s.K), options(),
                                              {uxf.data(), s.T, s.N}, {urf.data(), s.T, s.N});
  CHECK(ef == doctest::Approx(d.energy).epsilon(1e-5));
  CHECK(smg::test::relative_error(std::vector<double>(uxf.begin(), uxf.end()), d.ux) < 1e-4);
}
