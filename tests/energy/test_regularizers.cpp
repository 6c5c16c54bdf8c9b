// Tests of smg/energy/regularizers.hpp, the fused regulariser step: equal to the separate
// operators (node_confidences, carap, arap, lrm, accel: tests/support/operators.hpp, by the term
// list) for every subset of the terms, bit-identical
// for 1, 2 and 3 threads, float against double, the gradient against central differences, the
// hard cases, the memory bound and the argument checks.
//
// Bitwise or 1e-12? The confidences are always bit-identical (same element functions, same
// order). One energy alone (C-ARAP, ARAP or LRM) is bit-identical too: carap(), arap() and lrm()
// are the same driver (energy/driver.hpp) with the same term. With several energies the block
// partition follows the largest reach, and C-ARAP's and ARAP's d-gradients are summed before
// one back-propagation, so the comparison is ≤ 1e-12 relative to the largest value, in double.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "energy/fused_options.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/operators.hpp"
#include "support/prelude.hpp"

using smg::test::fused_options;
using smg::test::Scene;

namespace {

template <class S>
struct FusedOut {
  smg::RegularizerResult<S> e;
  std::vector<S> conf, gx, gr;
  // gr as the rotation gradient: raw quaternions [T][N][4] or the right tangent [T][N][3].
  smg::RotationGradientView<S> rotation_gradient(const Scene<S>& s, bool raw) {
    if (raw) return smg::QuaternionsView<S>(gr.data(), s.T, s.N);
    return smg::TangentsView<S>(gr.data(), s.T, s.N);
  }
};

// Zeroed gradient buffers (rotations raw [4] or tangent [3] per node) and confidences of −1.
template <class S>
FusedOut<S> fused_buffers(const Scene<S>& s, bool raw) {
  FusedOut<S> r;
  const std::size_t TN = static_cast<std::size_t>(s.T * s.N);
  r.conf.assign(TN, S(-1));
  r.gx.assign(TN * 3, S(0));
  r.gr.assign(TN * (raw ? 4 : 3), S(0));
  return r;
}

smg::ParallelOptions threads_option(int threads) {
  smg::ParallelOptions par;
  par.threads = threads;
  return par;
}

// The fused step; raw: rotation gradient as raw quaternions [T][N][4].
// given: the caller's confidences, passed when o.terms.confidence is off (null: none, c ≡ 1).
template <class S>
FusedOut<S> fused_run(const Scene<S>& s, const smg::RegularizerOptions& o, int threads,
                      bool raw = false, bool grad = true, bool vis = true,
                      smg::EnergyWorkspace<S>* ws = nullptr, std::vector<S>* given = nullptr) {
  FusedOut<S> r = fused_buffers(s, raw);
  const smg::ParallelOptions par = threads_option(threads);
  const smg::RotationGradientView<S> gr = grad ? r.rotation_gradient(s, raw) : smg::RotationGradientView<S>();
  const smg::VisibilityView<const std::uint8_t> v =
      vis ? s.visibility() : smg::VisibilityView<const std::uint8_t>();
  const smg::FrameScalarsView<S> c =
      o.terms.confidence ? smg::FrameScalarsView<S>(r.conf.data(), s.T, s.N)
      : given            ? smg::FrameScalarsView<S>(given->data(), s.T, s.N)
                         : smg::FrameScalarsView<S>();
  REQUIRE(smg::validate_regularizers<S>(s.positions(), s.rotations(), v, s.graph(), o, c,
                                        smg::PositionsView<S>(r.gx.data(), s.T, s.N), gr));
  r.e = smg::regularizers<S>(s.positions(), s.rotations(), v, s.graph(), o, c,
                             grad ? smg::PositionsView<S>(r.gx.data(), s.T, s.N)
                                  : smg::PositionsView<S>(),
                             gr, ws, par);
  return r;
}

// The same with the separate operators, by the term list: for every term that is on, in the
// list's order (the confidences first, which the others then read), its operator from
// tests/support/operators.hpp, its energy into the result's slot of the same name. A term on the
// list without its separate operator, or with an energy the result does not list, fails here.
template <class S>
FusedOut<S> fused_separate(const Scene<S>& s, const smg::RegularizerOptions& o, int threads,
                           bool raw = false, bool vis = true, const std::vector<S>* given = nullptr) {
  FusedOut<S> r = fused_buffers(s, raw);
  const smg::ParallelOptions par = threads_option(threads);
  const smg::RotationGradientView<S> gr = r.rotation_gradient(s, raw);
  const smg::PositionsView<S> gx(r.gx.data(), s.T, s.N);
  const smg::FrameScalarsView<S> conf(r.conf.data(), s.T, s.N);
  const smg::test::OperatorInputs<S> in{
      s.positions(), s.rotations(),
      vis ? s.visibility() : smg::VisibilityView<const std::uint8_t>(),
      o.terms.confidence ? smg::FrameScalarsView<const S>(r.conf.data(), s.T, s.N)
      : given            ? smg::FrameScalarsView<const S>(given->data(), s.T, s.N)
                         : smg::FrameScalarsView<const S>(),
      s.graph()};
  smg::for_each_term(o, [&](const char* term, bool on, const auto&) {
    if (!on) return;
    CAPTURE(term);
    int operators = 0, energies = 0;
    smg::test::for_each_operator([&](auto op) {
      using Op = decltype(op);
      if constexpr (Op::term != nullptr) {
        if (std::string(Op::term) != term) return;
        ++operators;
        const smg::Accumulator<S> e = Op::separate(in, o, gx, gr, conf, static_cast<smg::EnergyWorkspace<S>*>(nullptr), par);
        smg::RegularizerResult<S>::each_energy(
            [&](const char* name, smg::Accumulator<S>& slot) {
              if (std::string(name) != term) return;
              slot = e;
              ++energies;
            },
            r.e);
      }
    });
    CHECK(operators == 1);
    // The confidences are the one term without an energy.
    CHECK(energies == (std::string(term) == "confidence" ? 0 : 1));
  });
  return r;
}

// Bitwise equality of two runs' energies and gradients (the confidences are compared apart,
// where the caller's case computes them): what "bit-identical" promises for the fused step
// against the one-term operators and across thread counts.
template <class S>
void check_fused_bitwise(const FusedOut<S>& a, const FusedOut<S>& b) {
  smg::RegularizerResult<S>::each_energy(
      [](const char* name, const smg::Accumulator<S>& x, const smg::Accumulator<S>& y) {
        CAPTURE(name);
        CHECK(x == y);
      },
      a.e, b.e);
  CHECK(a.gx == b.gx);
  CHECK(a.gr == b.gr);
}

template <class S>
double fused_max_abs(const std::vector<S>& a) {
  double m = 0;
  for (S v : a) m = std::max(m, std::abs(static_cast<double>(v)));
  return m;
}

// max |a − b| / max(|b|, tiny) over the arrays.
template <class S>
double fused_rel_diff(const std::vector<S>& a, const std::vector<S>& b) {
  double d = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    d = std::max(d, std::abs(static_cast<double>(a[k]) - static_cast<double>(b[k])));
  return d / std::max(fused_max_abs(b), 1e-300);
}

double fused_rel(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); }

template <class S>
bool fused_all_finite(const FusedOut<S>& r) {
  auto fin = [](const std::vector<S>& v) {
    return std::all_of(v.begin(), v.end(), [](S x) { return std::isfinite(x); });
  };
  return fin(r.gx) && fin(r.gr) && std::isfinite(static_cast<double>(r.e.total()));
}

// Whether the fused step runs these options by nodes (energy/element_pass.hpp): the library's
// own rule, asked of the term list.
bool runs_by_nodes(const smg::RegularizerOptions& o, const Scene<double>& s) {
  smg::detail::RegularizerTermSet<double, std::int32_t> terms(s.T, s.N, s.K, s.N * s.K, o, true, true);
  return terms.apply(
      [](const auto&... t) { return smg::detail::element_schedule<double, std::int32_t>(t...); });
}

// Fused against separate on one scene, every subset of the terms on the list, tangent and raw.
void fused_check_equal(const Scene<double>& s, const std::string& what) {
  CAPTURE(what);
  using Result = smg::RegularizerResult<double>;
  const unsigned n_terms = smg::test::fused_term_count();
  auto bit = [](const char* term) { return 1u << smg::test::fused_term_index(term); };
  for (unsigned mask = 0; mask < (1u << n_terms); ++mask)
    for (bool raw : {false, true}) {
      CAPTURE(mask);
      CAPTURE(raw);
      const smg::RegularizerOptions o = fused_options(mask);
      const FusedOut<double> f = fused_run(s, o, 2, raw);
      const FusedOut<double> r = fused_separate(s, o, 2, raw);
      CHECK(fused_all_finite(f));
      if (o.terms.confidence) CHECK(f.conf == r.conf);  // bitwise: same functions, same order
      // One energy alone: the separate operator is the same driver with the same term, bitwise,
      // where both run the same schedule (the separate call reads the confidences, so a term that
      // runs by nodes alone runs in frame blocks beside computed confidences: to 1e-12 below).
      const unsigned energies = mask & ~bit("confidence");
      smg::RegularizerOptions alone = o;
      alone.terms.confidence = false;
      if (energies != 0 && (energies & (energies - 1)) == 0 && runs_by_nodes(o, s) == runs_by_nodes(alone, s))
        check_fused_bitwise(f, r);
      // Energies only (no gradient buffers: no spill, a different frame overlap).
      const FusedOut<double> fe = fused_run(s, o, 2, raw, false);
      Result::each_energy(
          [&](const char* name, double fused, double separate, double energy_only) {
            CAPTURE(name);
            CHECK(fused_rel(fused, separate) <= 1e-12);
            CHECK(fused_rel(energy_only, separate) <= 1e-12);
            // Terms that are off are exactly 0; those that are on vanish only where the
            // separate operator's does (LRM with one neighbour, one frame).
            CHECK((fused != 0.0) == (separate != 0.0));
            if ((mask & bit(name)) == 0) CHECK(fused == 0.0);
          },
          f.e, r.e, fe.e);
      CHECK(fused_rel_diff(f.gx, r.gx) <= 1e-12);
      CHECK(fused_rel_diff(f.gr, r.gr) <= 1e-12);
      CHECK(fused_max_abs(fe.gx) == 0.0);
      if (s.T > 4 && s.K > 1) {
        CHECK(((mask & bit("carap")) == 0) == (f.e.carap == 0.0));
        CHECK(((mask & bit("lrm")) == 0) == (f.e.lrm == 0.0));
        // Confidence-weighted smoothness vanishes exactly where every confidence is 0.
        const bool some_c = (mask & bit("confidence")) == 0 ||
                            std::any_of(f.conf.begin(), f.conf.end(), [](double c) { return c > 0; });
        if (some_c) CHECK(((mask & bit("accel")) == 0) == (f.e.accel == 0.0));
      }
    }
}

}  // namespace

TEST_CASE("fused regularizers equal the separate operators for every subset of the terms") {
  SMG_TEST_RNG(rng, 2401);
  // T = 23: three blocks of frames, the last one short; random degrees and weights.
  fused_check_equal(smg::test::random_scene(23, 30, 6, rng), "random graph");
  fused_check_equal(smg::test::rigid_bodies_scene(17, 40, 5), "rigid bodies");
}

TEST_CASE("fused regularizers equal the separate operators for every option value of every term") {
  // Every term on, then each named-enum option at each other value and each bool flipped
  // (smg::test::for_each_option_variant): a penalty, a form, a stop-gradient added to any term
  // is run here with no edit. Each value must change something (the energies or the gradients).
  SMG_TEST_RNG(rng, 2407);
  const Scene<double> s = smg::test::random_scene(13, 24, 5, rng);
  const smg::RegularizerOptions base = fused_options(smg::test::fused_all_terms());
  const FusedOut<double> f0 = fused_run(s, base, 2);
  const int calls = smg::test::for_each_option_variant(base, [&](const std::string& label,
                                                                 const smg::RegularizerOptions& o) {
    CAPTURE(label);
    const FusedOut<double> f = fused_run(s, o, 2);
    const FusedOut<double> r = fused_separate(s, o, 2);
    CHECK(fused_all_finite(f));
    smg::RegularizerResult<double>::each_energy(
        [&](const char* name, double fused, double separate) {
          CAPTURE(name);
          CHECK(fused_rel(fused, separate) <= 1e-12);
        },
        f.e, r.e);
    CHECK(fused_rel_diff(f.gx, r.gx) <= 1e-12);
    CHECK(fused_rel_diff(f.gr, r.gr) <= 1e-12);
    CHECK((f.gx != f0.gx || f.gr != f0.gr || f.e.total() != f0.e.total()));
  });
  CHECK(calls >= 15);
}

TEST_CASE("fused regularizers read the caller's confidences when they compute none") {
  // terms.confidence off and a confidence view given: every energy reads the caller's c as its
  // separate operator reads it (bitwise for one energy alone), the view is not written, and an
  // energy differs from its value with c ≡ 1 exactly where the separate operator's does (the
  // values are read, not ignored; terms that read no c, such as plain ARAP, are equal). No term
  // is named: which ones read c is the separate operators' business.
  SMG_TEST_RNG(rng, 2406);
  const Scene<double> s = smg::test::random_scene(23, 30, 6, rng);
  std::vector<double> given(s.c.size());
  for (double& c : given) c = rng.uniform(0.0, 1.0);
  const std::vector<double> kept = given;
  const unsigned conf_bit = 1u << smg::test::fused_term_index("confidence");
  int differing = 0;
  for (unsigned mask = 1; mask <= smg::test::fused_all_terms(); ++mask) {
    if (mask & conf_bit) continue;
    CAPTURE(mask);
    const smg::RegularizerOptions o = fused_options(mask);
    const FusedOut<double> f = fused_run<double>(s, o, 2, false, true, true, nullptr, &given);
    const FusedOut<double> r = fused_separate(s, o, 2, false, true, &given);
    const FusedOut<double> ones = fused_run(s, o, 2);
    const FusedOut<double> r_ones = fused_separate(s, o, 2);
    CHECK(given == kept);
    if ((mask & (mask - 1)) == 0) check_fused_bitwise(f, r);
    smg::RegularizerResult<double>::each_energy(
        [&](const char* name, double fused, double separate, double unit, double separate_unit) {
          CAPTURE(name);
          CHECK(fused_rel(fused, separate) <= 1e-12);
          CHECK((fused == unit) == (separate == separate_unit));
          if (fused != unit) ++differing;
        },
        f.e, r.e, ones.e, r_ones.e);
    CHECK(fused_rel_diff(f.gx, r.gx) <= 1e-12);
    CHECK(fused_rel_diff(f.gr, r.gr) <= 1e-12);
  }
  CHECK(differing > 0);
}

TEST_CASE("fused regularizers are bit-identical for 1, 2 and 3 threads") {
  SMG_TEST_RNG(rng, 2402);
  const Scene<double> sd = smg::test::random_scene(41, 36, 7, rng);
  const Scene<float> sf = sd.cast<float>();
  const smg::RegularizerOptions o = fused_options(smg::test::fused_all_terms());
  for (bool raw : {false, true}) {
    CAPTURE(raw);
    const FusedOut<double> d1 = fused_run(sd, o, 1, raw);
    const FusedOut<float> f1 = fused_run(sf, o, 1, raw);
    for (int threads : {2, 3}) {
      CAPTURE(threads);
      const FusedOut<double> d = fused_run(sd, o, threads, raw);
      const FusedOut<float> f = fused_run(sf, o, threads, raw);
      check_fused_bitwise(d, d1);
      CHECK(d.conf == d1.conf);
      check_fused_bitwise(f, f1);
      CHECK(f.conf == f1.conf);
    }
  }
}

TEST_CASE("fused regularizers in float agree with double") {
  const Scene<double> sd = smg::test::rigid_bodies_scene(20, 50, 6);
  const Scene<float> sf = sd.cast<float>();
  const smg::RegularizerOptions o = fused_options(smg::test::fused_all_terms());
  const FusedOut<double> d = fused_run(sd, o, 2);
  const FusedOut<float> f = fused_run(sf, o, 2);
  CHECK(fused_all_finite(f));
  CHECK(fused_rel(f.e.carap, d.e.carap) <= 1e-4);
  CHECK(fused_rel(f.e.arap, d.e.arap) <= 1e-4);
  CHECK(fused_rel(f.e.lrm, d.e.lrm) <= 1e-3);
  std::vector<double> gxf(f.gx.begin(), f.gx.end()), grf(f.gr.begin(), f.gr.end());
  CHECK(fused_rel_diff(gxf, d.gx) <= 1e-3);
  CHECK(fused_rel_diff(grf, d.gr) <= 1e-3);
  // Confidences: exp of ratios of small sums; float keeps a few digits.
  double dc = 0;
  for (std::size_t k = 0; k < d.conf.size(); ++k)
    dc = std::max(dc, std::abs(double(f.conf[k]) - d.conf[k]));
  CHECK(dc <= 1e-2);
}

TEST_CASE("fused regularizers' gradient matches central finite differences") {
  SMG_TEST_RNG(rng, 2403);
  Scene<double> s = smg::test::random_scene(7, 9, 4, rng);
  // The confidences are constants for the gradient (stop-gradient), so the function that is
  // differentiated has them held: c ≡ 1 (terms.confidence off) and α < 1 still weights C-ARAP.
  smg::RegularizerOptions o = fused_options(smg::test::fused_all_terms() & ~1u);  // all but the confidences
  o.lrm.huber_delta = 0.05;
  const FusedOut<double> f = fused_run(s, o, 2);
  auto energy = [&] {
    return static_cast<double>(fused_run(s, o, 1, false, false).e.total());
  };
  const std::vector<double> gx_fd = smg::test::central_gradient(s.x, energy, 1e-6);
  CHECK(fused_rel_diff(f.gx, gx_fd) <= 2e-7);
  std::vector<double> gr_fd(f.gr.size());
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i) {
      const Eigen::Quaterniond q0 = s.rot(t, i);
      for (int c = 0; c < 3; ++c)
        gr_fd[static_cast<std::size_t>((t * s.N + i) * 3 + c)] = smg::test::central_difference_tangent(
            q0, c, [&](const Eigen::Quaterniond& q) { s.set_rot(t, i, q); }, energy, 1e-6);
    }
  CHECK(fused_rel_diff(f.gr, gr_fd) <= 2e-7);
  CHECK(fused_max_abs(f.gx) > 0.0);
  CHECK(fused_max_abs(f.gr) > 0.0);
}

TEST_CASE("fused regularizers: hard cases equal the separate operators") {
  SMG_TEST_RNG(rng, 2404);
  {  // a node with no neighbours, and nobody's neighbour
    Scene<double> s = smg::test::random_scene(12, 15, 5, rng);
    for (Index k = 0; k < s.K; ++k) {
      s.idx[static_cast<std::size_t>(3 * s.K + k)] = -1;
      s.w[static_cast<std::size_t>(3 * s.K + k)] = 0.0;
    }
    // Node 3 is nobody's neighbour either: drop it from every row, valid entries first.
    for (Index i = 0; i < s.N; ++i) {
      Index n = 0;
      for (Index k = 0; k < s.K; ++k) {
        const std::size_t a = static_cast<std::size_t>(i * s.K + k);
        if (s.idx[a] < 0 || s.idx[a] == 3) continue;
        const std::size_t d = static_cast<std::size_t>(i * s.K + n++);
        s.idx[d] = s.idx[a];
        s.w[d] = s.w[a];
      }
      for (; n < s.K; ++n) {
        s.idx[static_cast<std::size_t>(i * s.K + n)] = -1;
        s.w[static_cast<std::size_t>(i * s.K + n)] = 0.0;
      }
    }
    fused_check_equal(s, "isolated node");
    const FusedOut<double> f = fused_run(s, fused_options(15), 1);
    double g3 = 0;
    for (Index t = 0; t < s.T; ++t)
      for (int c = 0; c < 3; ++c) g3 += std::abs(f.gx[static_cast<std::size_t>((t * s.N + 3) * 3 + c)]);
    CHECK(g3 == 0.0);
  }
  {  // every node invisible: all confidences 0
    Scene<double> s = smg::test::random_scene(10, 12, 4, rng);
    std::fill(s.v.begin(), s.v.end(), std::uint8_t(0));
    fused_check_equal(s, "all invisible");
    const FusedOut<double> f = fused_run(s, fused_options(1 | 2), 2);
    CHECK(fused_max_abs(f.conf) == 0.0);
  }
  {  // zero-length edges: two nodes on top of each other in every frame
    Scene<double> s = smg::test::random_scene(9, 10, 4, rng, true);
    for (Index t = 0; t < s.T; ++t) s.set_pos(t, s.idx[0], s.pos(t, 0));
    fused_check_equal(s, "zero-length edge");
  }
  {  // T smaller than the largest gap (4), T = 2 and T = 1
    for (Index T : {3, 2, 1}) {
      CAPTURE(T);
      fused_check_equal(smg::test::random_scene(T, 8, 3, rng), "short sequence");
    }
  }
  {  // K = 1
    fused_check_equal(smg::test::random_scene(11, 9, 1, rng), "K = 1");
  }
}

TEST_CASE("fused regularizers keep their extra memory under the inputs' size") {
  // A trainer-shaped case (more frames than two blocks of 32): the workspace the call fills is
  // what regularizers_extra_bytes says, and at most the bytes of positions, rotations,
  // visibility and graph; the separate operators' workspace holds several T·N·3 arrays.
  const Scene<double> s = smg::test::rigid_bodies_scene(96, 120, 8);
  const smg::RegularizerOptions o = fused_options(smg::test::fused_all_terms());
  for (int threads : {1, 2, 3}) {
    CAPTURE(threads);
    smg::EnergyWorkspace<double> ws;
    (void)fused_run(s, o, threads, true, true, true, &ws);
    smg::ParallelOptions par;
    par.threads = threads;
    const std::size_t predicted = smg::regularizers_extra_bytes<double, std::int32_t>(
        s.T, s.N, s.K, o, true, true, true, true, par);
    const std::size_t inputs = sizeof(double) * (s.x.size() + s.q.size() + s.w.size()) +
                               s.v.size() + sizeof(std::int32_t) * s.idx.size();
    CAPTURE(predicted);
    CAPTURE(inputs);
    CHECK(ws.bytes() == predicted);
    CHECK(ws.bytes() <= inputs);
  }
  // The separate operators are the same driver with one term (carap(), lrm()): their workspace
  // keeps the same bound, on their own inputs (no visibility; lrm() reads no rotations).
  std::vector<double> gx(s.x.size()), gr(s.x.size());
  const std::size_t graph_bytes = sizeof(double) * s.w.size() + sizeof(std::int32_t) * s.idx.size();
  smg::EnergyWorkspace<double> ws_lrm, ws_carap;
  (void)smg::lrm<double>(s.positions(), s.confidence(), s.graph(), o.lrm,
                         smg::PositionsView<double>(gx.data(), s.T, s.N), &ws_lrm);
  (void)smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o.carap,
                           smg::PositionsView<double>(gx.data(), s.T, s.N),
                           smg::TangentsView<double>(gr.data(), s.T, s.N), &ws_carap);
  CHECK(ws_lrm.bytes() > 0);
  CHECK(ws_lrm.bytes() <= sizeof(double) * s.x.size() + graph_bytes);
  CHECK(ws_carap.bytes() <= sizeof(double) * (s.x.size() + s.q.size()) + graph_bytes);
}

namespace {
// Trajectory smoothness and the rotation-angle term without C-ARAP, ARAP, LRM, relrot or
// computed confidences (options `computed`: the confidences on, which read the graph).
smg::RegularizerOptions graph_free_options(bool computed) {
  smg::RegularizerOptions o;
  o.terms.confidence = computed;
  o.terms.carap = o.terms.arap = o.terms.lrm = o.terms.relrot = false;
  o.terms.accel = o.terms.angle = true;
  o.accel.penalty = smg::Penalty::norm;
  o.accel.normalization = smg::Normalization::mean;
  o.angle.form = smg::AccelForm::velocity;
  return o;
}
}  // namespace

TEST_CASE("graph-free terms run by nodes: the frame blocks' results, every core, no scratch") {
  // energy/element_pass.hpp: accel and angle alone run as per-(frame, node) elements over chunks
  // of nodes; with the confidences computed beside them (they read the graph, and accel and
  // angle do not read them here) the same terms run in frame blocks. Short windows (one block
  // there) and a long one; N over several chunks of 256 nodes.
  SMG_TEST_RNG(rng, 2406);
  for (const auto& shape : {std::pair<smg::Index, smg::Index>{2, 700}, {3, 1100}, {5, 300}, {41, 600}}) {
    const smg::Index T = shape.first, N = shape.second;
    CAPTURE(T);
    CAPTURE(N);
    const Scene<double> sd = smg::test::random_scene(T, N, 5, rng);
    const Scene<float> sf = sd.cast<float>();
    for (bool raw : {false, true}) {
      CAPTURE(raw);
      const FusedOut<double> nodes = fused_run(sd, graph_free_options(false), 1, raw);
      const FusedOut<double> blocks = fused_run(sd, graph_free_options(true), 1, raw);
      CHECK(fused_rel(nodes.e.accel, blocks.e.accel) <= 1e-13);
      CHECK(fused_rel(nodes.e.angle, blocks.e.angle) <= 1e-13);
      CHECK(fused_rel_diff(nodes.gx, blocks.gx) <= 1e-13);
      CHECK(fused_rel_diff(nodes.gr, blocks.gr) <= 1e-13);
      // Bit-identical for any thread count (the chunks are a function of N only).
      const FusedOut<float> f1 = fused_run(sf, graph_free_options(false), 1, raw);
      for (int threads : {2, 3, 4}) {
        CAPTURE(threads);
        check_fused_bitwise(fused_run(sd, graph_free_options(false), threads, raw), nodes);
        check_fused_bitwise(fused_run(sf, graph_free_options(false), threads, raw), f1);
      }
    }
    // No scratch: the workspace stays empty, as regularizers_extra_bytes says.
    smg::EnergyWorkspace<double> ws;
    (void)fused_run(sd, graph_free_options(false), 2, false, true, true, &ws);
    CHECK(ws.bytes() == 0);
    CHECK(smg::regularizers_extra_bytes<double, std::int32_t>(T, N, 5, graph_free_options(false), true, true,
                                                              true, true) == 0);
    CHECK(smg::regularizers_extra_bytes<double, std::int32_t>(T, N, 5, graph_free_options(true), true, true,
                                                              true, true) > 0);
  }
}

TEST_CASE("validate_regularizers names the bad argument in one line") {
  SMG_TEST_RNG(rng, 2405);
  Scene<double> s = smg::test::random_scene(5, 6, 3, rng);
  std::vector<double> conf(static_cast<std::size_t>(s.T * s.N)), gx(s.x.size()), gr(s.x.size());
  const smg::FrameScalarsView<double> c(conf.data(), s.T, s.N);
  const smg::PositionsView<double> g(gx.data(), s.T, s.N);
  auto check = [&](const smg::Status& st, const std::string& name) {
    CAPTURE(st.message());
    CHECK(!st);
    CHECK(st.message().find(name) != std::string::npos);
    CHECK(st.message().find('\n') == std::string::npos);
  };
  smg::RegularizerOptions o = fused_options(15);
  CHECK(smg::validate_regularizers<double>(s.positions(), s.rotations(), s.visibility(), s.graph(),
                                           o, c, g, smg::TangentsView<double>(gr.data(), s.T, s.N)));
  // Rotations of the wrong length.
  check(smg::validate_regularizers<double>(s.positions(),
                                           smg::QuaternionsView<const double>(s.q.data(), s.T, s.N - 1),
                                           s.visibility(), s.graph(), o),
        "rotations");
  // No rotations are fine without C-ARAP and ARAP.
  o.terms.carap = o.terms.arap = false;
  CHECK(smg::validate_regularizers<double>(s.positions(), {}, s.visibility(), s.graph(), o));
  o = fused_options(15);
  o.carap.alpha = 1.5;
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o),
        "CarapOptions.alpha");
  o = fused_options(15);
  o.lrm.huber_delta = 0;
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o),
        "LrmOptions.huber_delta");
  o = fused_options(14);  // confidences off: `confidence` is the caller's, read, in [0, 1]
  CHECK(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o, c));
  conf[3] = 1.5;
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o, c),
        "confidence");
  conf[3] = std::nan("");
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o, c),
        "confidence");
  conf[3] = 0;
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o,
                                           smg::FrameScalarsView<double>(conf.data(), s.T, s.N - 1)),
        "confidence");
  o = fused_options(15);
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o, c,
                                           smg::PositionsView<double>(gx.data(), s.T - 1, s.N)),
        "grad_positions");
  s.x[4] = std::nan("");
  check(smg::validate_regularizers<double>(s.positions(), s.rotations(), {}, s.graph(), o),
        "positions");
}
