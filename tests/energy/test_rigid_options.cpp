// The rigid energies' penalties, stop-gradient and frame (E24; CarapOptions / ArapOptions::penalty,
// ::stop_gradient, ::penalty_eps, ::frame): each penalty and frame against the energy written out
// here in plain loops (its own rotation matrix, its own sums), C-ARAP and ARAP, sum and mean,
// each part alone; the neighbour's frame against the row's frame on the reversed graph;
// the stop-gradient by two identities (the held row's and the held neighbour's gradients add up
// to the full one; holding the neighbour equals a graph whose neighbours are constant copies);
// sqrt_weighted's zero-weight edges (m λ sqrt(ε) each, no gradient); torch's exact zeros on a
// still window; the options' validation. Central differences, AutoDiffScalar, float, threads
// and hard cases run for every penalty through the operator list (tests/support/operators.hpp's
// WithPenalty, tests/energy/test_terms.cpp); fused against separate and the CUDA host scheme
// for every value through smg::test::for_each_option_variant.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/finite_diff.hpp"
#include "support/prelude.hpp"

namespace {

using smg::Index;
using smg::test::Scene;

// (E9) with each part under (E24) written out, in double: rows i, slots k, gaps δ, frames t.
double rigid_reference(const Scene<double>& s, const smg::CarapOptions& o, bool with_confidence) {
  Index pairs = 0, edges = 0;
  for (const smg::Gap& g : o.gaps) pairs += std::max<Index>(0, s.T - g.delta);
  for (Index i = 0; i < s.N; ++i)
    for (Index k = 0; k < s.K; ++k) edges += s.idx[static_cast<std::size_t>(i * s.K + k)] >= 0 ? 1 : 0;
  const double scale =
      o.normalization == smg::Normalization::mean ? (pairs * edges > 0 ? o.weight / double(pairs * edges) : 0.0)
                                                  : o.weight;
  auto d_of = [&](Index t, Index i, Index j) {
    const Index f = o.frame == smg::RigidFrame::neighbor ? j : i;  // whose rotation (E24)
    const Eigen::Matrix3d R = s.rot(t, f).normalized().toRotationMatrix();
    return Eigen::Vector3d(R.transpose() * (s.pos(t, j) - s.pos(t, i)));
  };
  double e = 0;
  for (const smg::Gap& g : o.gaps)
    for (Index t = 0; t + g.delta < s.T; ++t)
      for (Index i = 0; i < s.N; ++i)
        for (Index k = 0; k < s.K; ++k) {
          const Index j = s.idx[static_cast<std::size_t>(i * s.K + k)];
          if (j < 0) break;
          const double c = with_confidence ? s.c[static_cast<std::size_t>(t * s.N + j)] : 1.0;
          const double w = s.w[static_cast<std::size_t>(i * s.K + k)] * (o.alpha + (1 - o.alpha) * c);
          const Eigen::Vector3d d0 = d_of(t, i, j), d1 = d_of(t + g.delta, i, j);
          const double rc = (d1 - d0).norm(), rl = d1.norm() - d0.norm();
          const double m = g.weight * scale;
          switch (o.penalty) {
            case smg::Penalty::squared: e += m * w * (o.lambda_c * rc * rc + o.lambda_l * rl * rl); break;
            case smg::Penalty::norm: e += m * w * (o.lambda_c * rc + o.lambda_l * std::abs(rl)); break;
            case smg::Penalty::sqrt_weighted:
              if (o.lambda_c != 0) e += m * o.lambda_c * std::sqrt(w * rc * rc + o.penalty_eps);
              if (o.lambda_l != 0) e += m * o.lambda_l * std::sqrt(w * rl * rl + o.penalty_eps);
              break;
          }
        }
  return e;
}

struct RigidOut {
  double energy = 0;
  std::vector<double> gx, gr;
};

RigidOut rigid_run(const Scene<double>& s, const smg::CarapOptions& o, bool with_confidence, int threads = 2) {
  RigidOut r;
  r.gx.assign(static_cast<std::size_t>(3 * s.T * s.N), 0.0);
  r.gr.assign(static_cast<std::size_t>(3 * s.T * s.N), 0.0);
  const smg::FrameScalarsView<const double> c =
      with_confidence ? s.confidence() : smg::FrameScalarsView<const double>();
  const smg::PositionsView<double> gx(r.gx.data(), s.T, s.N);
  const smg::TangentsView<double> gr(r.gr.data(), s.T, s.N);
  REQUIRE(smg::validate_carap<double>(s.positions(), s.rotations(), c, s.graph(), o, gx, gr));
  smg::ParallelOptions par;
  par.threads = threads;
  r.energy = smg::carap<double>(s.positions(), s.rotations(), c, s.graph(), o, gx, gr, nullptr, par);
  return r;
}

// rigid_run with C-ARAP's defaults but the penalty and the stop-gradient.
RigidOut rigid_held(const Scene<double>& s, smg::Penalty penalty, smg::StopGradient hold, bool with_confidence) {
  smg::CarapOptions o;
  o.penalty = penalty;
  o.stop_gradient = hold;
  return rigid_run(s, o, with_confidence);
}

}  // namespace

TEST_CASE("rigid options: the defaults are the paper's (squared, no stop-gradient)") {
  CHECK(smg::CarapOptions{}.penalty == smg::Penalty::squared);
  CHECK(smg::ArapOptions{}.penalty == smg::Penalty::squared);
  CHECK(smg::CarapOptions{}.stop_gradient == smg::StopGradient::none);
  CHECK(smg::ArapOptions{}.penalty_eps == 1e-20);
  CHECK(std::string(smg::to_string(smg::kStopGradients[1])) == "row");
}

TEST_CASE("rigid penalties: C-ARAP and ARAP equal the written-out (E24), each part, sum and mean") {
  SMG_TEST_RNG(rng, 4301);
  // T = 2 and 3: windows the rigid term runs with frame-major lanes (lanes_over_edges).
  for (const Index T : {9, 2, 3}) {
  CAPTURE(T);
  Scene<double> s = smg::test::random_scene(T, 14, 4, rng);
  s.w[3] = 0.0;  // a zero-weight edge: sqrt_weighted still counts it
  for (const smg::Penalty penalty : smg::kPenalties)
    for (const smg::Normalization nm : {smg::Normalization::sum, smg::Normalization::mean})
      for (const int parts : {0, 1, 2})  // both parts, vector part alone, length part alone
        for (const bool plain : {false, true})
          for (const smg::RigidFrame frame : smg::kRigidFrames) {
          CAPTURE(smg::to_string(penalty));
          CAPTURE(smg::to_string(frame));
          CAPTURE(nm == smg::Normalization::mean);
          CAPTURE(parts);
          CAPTURE(plain);
          smg::ArapOptions a;
          a.penalty = penalty;
          a.normalization = nm;
          a.lambda_c = parts == 2 ? 0.0 : 1.3;
          a.lambda_l = parts == 1 ? 0.0 : 0.7;
          a.gaps = {{1, 1.0}, {3, 0.5}};
          a.weight = 0.9;
          a.penalty_eps = 1e-4;  // large enough to matter in the value
          a.frame = frame;
          smg::CarapOptions o = smg::carap_options_for_arap(a);  // α = 1: the reference's ARAP
          double e = 0;
          if (plain) {
            REQUIRE(smg::validate_arap<double>(s.positions(), s.rotations(), s.graph(), a));
            e = smg::arap<double>(s.positions(), s.rotations(), s.graph(), a);
          } else {
            o.alpha = 0.6;
            e = rigid_run(s, o, true).energy;
          }
          const double ref = rigid_reference(s, o, !plain);
          CHECK(ref > 0);
          CHECK(std::abs(e - ref) <= 1e-12 * ref);
        }
  }
}

TEST_CASE("rigid stop-gradient: held row + held neighbour = the full gradient; rotations and energy unchanged") {
  SMG_TEST_RNG(rng, 4302);
  const Scene<double> s = smg::test::random_scene(8, 16, 5, rng);
  for (const smg::Penalty penalty : smg::kPenalties) {
    CAPTURE(smg::to_string(penalty));
    const RigidOut full = rigid_held(s, penalty, smg::StopGradient::none, true);
    const RigidOut row = rigid_held(s, penalty, smg::StopGradient::row, true);
    const RigidOut nbr = rigid_held(s, penalty, smg::StopGradient::neighbor, true);
    CHECK(row.energy == full.energy);
    CHECK(nbr.energy == full.energy);
    CHECK(row.gr == full.gr);
    CHECK(nbr.gr == full.gr);
    std::vector<double> sum(full.gx.size());
    for (std::size_t k = 0; k < sum.size(); ++k) sum[k] = row.gx[k] + nbr.gx[k];
    CHECK(smg::test::relative_error(sum, full.gx) < 1e-13);
    CHECK(row.gx != full.gx);
    CHECK(nbr.gx != full.gx);
  }
}

TEST_CASE("rigid stop-gradient: a held neighbour equals a graph whose neighbours are constant copies") {
  // Nodes N..2N−1 copy nodes 0..N−1 (same positions and rotations); row i's neighbour j becomes
  // the copy N + j. The copies' gradients are dropped, as a detached input's are: rows 0..N−1
  // then get exactly what stop_gradient=neighbor gives on the original graph.
  SMG_TEST_RNG(rng, 4303);
  const Scene<double> s = smg::test::random_scene(7, 12, 4, rng);
  Scene<double> d;
  d.resize(s.T, 2 * s.N);
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < 2 * s.N; ++i) {
      d.set_pos(t, i, s.pos(t, i % s.N));
      d.set_rot(t, i, s.rot(t, i % s.N));
    }
  d.K = s.K;
  d.idx.assign(static_cast<std::size_t>(2 * s.N * s.K), -1);
  d.w.assign(static_cast<std::size_t>(2 * s.N * s.K), 0.0);
  for (Index k = 0; k < s.N * s.K; ++k) {
    const std::int32_t j = s.idx[static_cast<std::size_t>(k)];
    d.idx[static_cast<std::size_t>(k)] = j < 0 ? -1 : j + static_cast<std::int32_t>(s.N);
    d.w[static_cast<std::size_t>(k)] = s.w[static_cast<std::size_t>(k)];
  }
  for (const smg::Penalty penalty : smg::kPenalties) {
    CAPTURE(smg::to_string(penalty));
    const RigidOut copies = rigid_held(d, penalty, smg::StopGradient::none, false);
    const RigidOut held = rigid_held(s, penalty, smg::StopGradient::neighbor, false);
    CHECK(std::abs(copies.energy - held.energy) <= 1e-13 * held.energy);
    for (Index t = 0; t < s.T; ++t)
      for (Index i = 0; i < s.N; ++i)
        for (int c = 0; c < 3; ++c) {
          const std::size_t a = static_cast<std::size_t>((t * s.N + i) * 3 + c);
          const std::size_t b = static_cast<std::size_t>((t * 2 * s.N + i) * 3 + c);
          CHECK(std::abs(held.gx[a] - copies.gx[b]) <= 1e-12);
          CHECK(std::abs(held.gr[a] - copies.gr[b]) <= 1e-12);
        }
  }
}

TEST_CASE("rigid sqrt_weighted: a zero-weight edge adds m λ sqrt(ε) per pair and no gradient") {
  SMG_TEST_RNG(rng, 4304);
  Scene<double> s = smg::test::random_scene(6, 10, 3, rng);
  // Row 2's last listed neighbour: weight 0 in one graph, removed (padding) in the other.
  Index k_last = s.K - 1;
  while (s.idx[static_cast<std::size_t>(2 * s.K + k_last)] < 0) --k_last;
  Scene<double> removed = s;
  s.w[static_cast<std::size_t>(2 * s.K + k_last)] = 0.0;
  removed.idx[static_cast<std::size_t>(2 * s.K + k_last)] = -1;
  removed.w[static_cast<std::size_t>(2 * s.K + k_last)] = 0.0;
  smg::CarapOptions o;
  o.penalty = smg::Penalty::sqrt_weighted;
  o.gaps = {{1, 1.0}, {2, 0.5}};
  o.lambda_c = 1.0;
  o.lambda_l = 0.25;
  o.penalty_eps = 1e-6;
  const RigidOut a = rigid_run(s, o, true), b = rigid_run(removed, o, true);
  // Σ_δ γ_δ (T − δ) (λc + λl) sqrt(ε)
  const double floor = (1.0 * 5 + 0.5 * 4) * (1.0 + 0.25) * 1e-3;
  CHECK(std::abs((a.energy - b.energy) - floor) <= 1e-12 * a.energy);
  CHECK(smg::test::relative_error(a.gx, b.gx) < 1e-14);
  CHECK(smg::test::relative_error(a.gr, b.gr) < 1e-14);
  // norm and squared: a zero weight adds exactly nothing.
  for (const smg::Penalty p : {smg::Penalty::squared, smg::Penalty::norm}) {
    o.penalty = p;
    CHECK(rigid_run(s, o, true).energy == rigid_run(removed, o, true).energy);
  }
}

TEST_CASE("rigid norm: a still window has energy 0 and a gradient of exactly 0, as torch's norm") {
  SMG_TEST_RNG(rng, 4305);
  Scene<double> s = smg::test::random_scene(6, 10, 3, rng);
  for (Index t = 1; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i) {
      s.set_pos(t, i, s.pos(0, i));
      s.set_rot(t, i, s.rot(0, i));
    }
  smg::CarapOptions o;
  o.penalty = smg::Penalty::norm;
  const RigidOut r = rigid_run(s, o, true);
  CHECK(r.energy == 0.0);
  CHECK(std::all_of(r.gx.begin(), r.gx.end(), [](double v) { return v == 0.0; }));
  CHECK(std::all_of(r.gr.begin(), r.gr.end(), [](double v) { return v == 0.0; }));
}

namespace {
// The graph with every edge i -> j (weight w) reversed to j -> i (weight w), in (i, slot) order;
// K grows to the largest in-degree.
Scene<double> reversed(const Scene<double>& s) {
  std::vector<std::vector<std::pair<std::int32_t, double>>> in(static_cast<std::size_t>(s.N));
  for (Index i = 0; i < s.N; ++i)
    for (Index k = 0; k < s.K; ++k) {
      const std::int32_t j = s.idx[static_cast<std::size_t>(i * s.K + k)];
      if (j < 0) break;
      in[static_cast<std::size_t>(j)].emplace_back(static_cast<std::int32_t>(i), s.w[static_cast<std::size_t>(i * s.K + k)]);
    }
  Index K = 1;
  for (const auto& v : in) K = std::max<Index>(K, static_cast<Index>(v.size()));
  Scene<double> r = s;
  r.K = K;
  r.idx.assign(static_cast<std::size_t>(s.N * K), -1);
  r.w.assign(static_cast<std::size_t>(s.N * K), 0.0);
  for (Index j = 0; j < s.N; ++j)
    for (std::size_t a = 0; a < in[static_cast<std::size_t>(j)].size(); ++a) {
      r.idx[static_cast<std::size_t>(j * K) + a] = in[static_cast<std::size_t>(j)][a].first;
      r.w[static_cast<std::size_t>(j * K) + a] = in[static_cast<std::size_t>(j)][a].second;
    }
  return r;
}
}  // namespace

TEST_CASE("rigid frame: the neighbour's frame on a graph equals the row's frame on the reversed graph") {
  // ‖R_jᵀ(x_j − x_i)‖ terms of edge i -> j are the row-frame terms of edge j -> i (the sign of d
  // cancels in every difference): energy, position and rotation gradients agree for every
  // penalty and stop-gradient (a held neighbour of i -> j is the held row of j -> i). Without
  // confidences: C-ARAP's weight reads the neighbour's confidence, which reversing would move.
  SMG_TEST_RNG(rng, 4306);
  const Scene<double> s = smg::test::random_scene(7, 13, 4, rng);
  const Scene<double> r = reversed(s);
  for (const smg::Penalty penalty : smg::kPenalties)
    for (const smg::StopGradient hold : smg::kStopGradients)
      for (const int threads : {1, 3}) {
        CAPTURE(smg::to_string(penalty));
        CAPTURE(smg::to_string(hold));
        smg::CarapOptions o;
        o.penalty = penalty;
        o.gaps = {{1, 1.0}, {2, 0.4}, {5, 0.2}};
        o.penalty_eps = 1e-6;
        o.stop_gradient = hold;
        o.frame = smg::RigidFrame::neighbor;
        const RigidOut a = rigid_run(s, o, false, threads);
        o.frame = smg::RigidFrame::row;
        o.stop_gradient = hold == smg::StopGradient::row        ? smg::StopGradient::neighbor
                          : hold == smg::StopGradient::neighbor ? smg::StopGradient::row
                                                                : hold;
        const RigidOut b = rigid_run(r, o, false, threads);
        CHECK(a.energy > 0);
        CHECK(std::abs(a.energy - b.energy) <= 1e-13 * a.energy);
        CHECK(smg::test::relative_error(a.gx, b.gx) < 1e-13);
        CHECK(smg::test::relative_error(a.gr, b.gr) < 1e-13);
        // ... and not the row's frame on the same graph.
        const RigidOut c = rigid_run(s, o, false, threads);
        CHECK(smg::test::relative_error(a.gr, c.gr) > 1e-3);
      }
}

TEST_CASE("rigid frame: bit-identical for any thread count, and the gradient of the rotations reaches the neighbours") {
  SMG_TEST_RNG(rng, 4307);
  const Scene<double> s = smg::test::random_scene(70, 9, 5, rng);  // several blocks of frames
  smg::CarapOptions o;
  o.frame = smg::RigidFrame::neighbor;
  o.gaps = {{1, 1.0}, {4, 0.5}};
  const RigidOut one = rigid_run(s, o, true, 1), four = rigid_run(s, o, true, 4);
  CHECK(one.energy == four.energy);
  CHECK(one.gx == four.gx);
  CHECK(one.gr == four.gr);
  // A node nobody lists as a neighbour gets no rotation gradient in the neighbour's frame.
  Scene<double> lone = s;
  for (Index k = 0; k < lone.N * lone.K; ++k)
    if (lone.idx[static_cast<std::size_t>(k)] == 0) lone.w[static_cast<std::size_t>(k)] = 0.0;
  const RigidOut z = rigid_run(lone, o, true, 2);
  for (Index t = 0; t < s.T; ++t)
    for (int c = 0; c < 3; ++c) CHECK(z.gr[static_cast<std::size_t>(t * s.N * 3 + c)] == 0.0);
}

TEST_CASE("rigid options: validation names the option; one fused call holds one endpoint") {
  smg::CarapOptions o;
  o.penalty = static_cast<smg::Penalty>(7);
  CHECK(std::string(smg::validate_options(o).message()) ==
        "CarapOptions.penalty must be squared, norm or sqrt_weighted, got 7");
  o = {};
  o.stop_gradient = static_cast<smg::StopGradient>(5);
  CHECK(std::string(smg::validate_options(o).message()) ==
        "CarapOptions.stop_gradient must be none, row or neighbor, got 5");
  smg::ArapOptions a;
  a.penalty_eps = 0.0;
  CHECK(std::string(smg::validate_options(a).message()).rfind("ArapOptions.penalty_eps", 0) == 0);
  smg::RegularizerOptions r;
  r.terms.arap = true;
  r.carap.stop_gradient = smg::StopGradient::row;
  const smg::Status st = smg::validate_options(r);
  CHECK(!st);
  CHECK(std::string(st.message()).rfind("RegularizerOptions: carap.stop_gradient (row) and arap.stop_gradient (none) differ", 0) == 0);
  r.arap.stop_gradient = smg::StopGradient::row;
  CHECK(smg::validate_options(r));
  r.arap.frame = smg::RigidFrame::neighbor;
  CHECK(std::string(smg::validate_options(r).message()).rfind("RegularizerOptions: carap.frame (row) and arap.frame (neighbor) differ", 0) == 0);
  r.carap.frame = smg::RigidFrame::neighbor;
  CHECK(smg::validate_options(r));
  o = {};
  o.frame = static_cast<smg::RigidFrame>(2);
  CHECK(std::string(smg::validate_options(o).message()) == "CarapOptions.frame must be row or neighbor, got 2");
}
