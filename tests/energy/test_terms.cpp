// The properties every regulariser must have, checked for every operator of the list
// (tests/support/operators.hpp), as manif's common tester does for every group: an operator
// added to the list is covered here without a line of its own.
//   - the gradient (where it is the exact gradient of the energy) against central differences
//     in double and against Eigen's AutoDiffScalar through the same code;
//   - float against double;
//   - bit-identical results for 1, 2 and 3 threads;
//   - finite results on the hard cases (all confidences zero, zero-length edges, coincident
//     frames, huge and tiny coordinates, one and two frames).
//   - argument errors: the validator takes the good arguments and refuses a NaN position, an
//     out-of-range neighbour, a bad confidence, visibility or quaternion (where the operator
//     reads them) and an output of the wrong shape, each with a message naming the argument.
// The int32/int64 graphs, the caller's executor and mutable views are tests/api's, over the
// same list.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "energy/operator_runs.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/autodiff.hpp"
#include "support/finite_diff.hpp"
#include "support/operators.hpp"
#include "support/prelude.hpp"

using smg::test::AD;
using smg::test::all_finite;
using smg::test::Outputs;
using smg::test::run_op;
using smg::test::same_bits;
using smg::test::Scene;
using smg::test::term_scene;

// T = 9: blocks of 8 frames and a short last one; T = 2 and 3: the windows of Dynamic 3D
// Gaussians and Shape of Motion, whose blocks the rigid term runs with frame-major lanes
// (RigidTerm::lanes_over_edges).
TEST_CASE("every operator with an exact gradient matches central differences") {
  for (const smg::Index T : {9, 2, 3}) {
    CAPTURE(T);
    Scene<double> s = term_scene(T, 10, 4, 3501);
    smg::test::every_operator([&](auto op) {
      using Op = decltype(op);
      if constexpr (Op::exact_gradient) {
        const Outputs<double> a = run_op<Op>(s, 1);
        if (T == 2 && a.energy == 0) {  // a second difference (accel, angle) has no term in 2 frames
          CHECK(std::all_of(a.gx.begin(), a.gx.end(), [](double v) { return v == 0.0; }));
          CHECK(std::all_of(a.gr.begin(), a.gr.end(), [](double v) { return v == 0.0; }));
          return;
        }
        CHECK(a.energy > 0);
        smg::test::check_gradient_fd<Op>(s, 1e-7);
      }
    });
  }
}

TEST_CASE("every operator with an exact gradient equals AutoDiffScalar through its own code") {
  for (const smg::Index T : {7, 2, 3}) {
    CAPTURE(T);
    const Scene<double> s = term_scene(T, 6, 3, 3502);
    // Positions are variables 0..3TN−1, rotations q ⊗ Exp(φ) with φ the variables 3TN..6TN−1.
    const smg::Index TN = s.T * s.N, vars = 6 * TN;
    std::vector<AD> x, q, c, w;
    for (smg::Index k = 0; k < 3 * TN; ++k) x.push_back(AD(s.x[k], vars, k));
    for (smg::Index k = 0; k < TN; ++k) {
      Eigen::Matrix<AD, 3, 1> phi;
      for (int d = 0; d < 3; ++d) phi(d) = AD(0.0, vars, 3 * TN + 3 * k + d);
      const Eigen::Quaternion<AD> q0(AD(s.q[4 * k]), AD(s.q[4 * k + 1]), AD(s.q[4 * k + 2]),
                                     AD(s.q[4 * k + 3]));
      const Eigen::Quaternion<AD> r = q0 * smg::so3::exp(phi);
      for (const AD& v : {r.w(), r.x(), r.y(), r.z()}) q.push_back(v);
    }
    for (double v : s.c) c.push_back(AD(v));
    for (double v : s.w) w.push_back(AD(v));
    const smg::test::OperatorInputs<AD> in{{x.data(), s.T, s.N}, {q.data(), s.T, s.N},
                                           s.visibility(), {c.data(), s.T, s.N},
                                           {s.idx.data(), w.data(), s.N, s.K}};
    smg::ParallelOptions par;
    par.threads = 1;
    smg::test::every_operator([&](auto op) {
      using Op = decltype(op);
      if constexpr (Op::exact_gradient) {
        const AD e = Op::run(in, smg::test::OperatorOutputs<AD>{},
                             static_cast<smg::EnergyWorkspace<AD>*>(nullptr), par);
        const Outputs<double> a = run_op<Op>(s, 1);
        CHECK(std::abs(e.value() - a.energy) <= 1e-12 * std::abs(a.energy));
        if (T == 2 && a.energy == 0) {  // no term in 2 frames: a constant, no derivatives
          CHECK(e.value() == 0.0);
          return;
        }
        REQUIRE(e.derivatives().size() == vars);
        std::vector<double> dx(e.derivatives().data(), e.derivatives().data() + 3 * TN);
        std::vector<double> dr(e.derivatives().data() + 3 * TN, e.derivatives().data() + vars);
        CHECK(smg::test::relative_error(a.gx, dx) < 1e-10);
        if (std::any_of(dr.begin(), dr.end(), [](double v) { return v != 0.0; }))
          CHECK(smg::test::relative_error(a.gr, dr) < 1e-10);
        else
          CHECK(std::all_of(a.gr.begin(), a.gr.end(), [](double v) { return v == 0.0; }));
      }
    });
  }
}

TEST_CASE("every operator in float agrees with double") {
  const Scene<double> sd = term_scene(20, 30, 6, 3503);
  smg::test::every_operator([&](auto op) {
    using Op = decltype(op);
    const Outputs<double> d = run_op<Op>(sd, 2);
    const Outputs<float> f = run_op<Op>(sd.cast<float>(), 2);
    CHECK(all_finite(f));
    CHECK(std::abs(f.energy - d.energy) <= 1e-4 * std::abs(d.energy));
    CHECK(smg::test::relative_error(f.gx, d.gx) <= 1e-3);
    CHECK(smg::test::relative_error(f.gr, d.gr) <= 1e-3);
    double dc = 0;  // confidences: exp of ratios of small sums; float keeps a few digits
    for (std::size_t k = 0; k < d.c.size(); ++k)
      dc = std::max(dc, std::abs(static_cast<double>(f.c[k]) - d.c[k]));
    CHECK(dc <= 1e-2);
  });
}

TEST_CASE("every operator is bit-identical for 1, 2 and 3 threads") {
  // T = 41: several blocks of frames, the last one short.
  const Scene<double> sd = term_scene(41, 36, 7, 3504);
  const Scene<float> sf = sd.cast<float>();
  smg::test::every_operator([&](auto op) {
    using Op = decltype(op);
    const Outputs<double> d1 = run_op<Op>(sd, 1);
    const Outputs<float> f1 = run_op<Op>(sf, 1);
    for (int threads : {2, 3}) {
      CAPTURE(threads);
      CHECK(same_bits(run_op<Op>(sd, threads), d1));
      CHECK(same_bits(run_op<Op>(sf, threads), f1));
    }
  });
}

TEST_CASE("every operator stays finite on the hard cases") {
  struct Case {
    std::string name;
    Scene<double> s;
  };
  std::vector<Case> cases;
  // A small scene changed by `edit`.
  auto add = [&](const char* name, smg::Index T, unsigned seed, auto&& edit) {
    Scene<double> s = term_scene(T, 8, 3, seed);
    edit(s);
    cases.push_back({name, s});
  };
  add("all confidences zero", 6, 3505, [](Scene<double>& s) {  // and every node hidden
    std::fill(s.c.begin(), s.c.end(), 0.0);
    std::fill(s.v.begin(), s.v.end(), std::uint8_t(0));
  });
  add("zero-length edges", 6, 3506, [](Scene<double>& s) {  // every node at one point
    for (smg::Index k = 0; k < s.T * s.N; ++k) s.set_pos(k / s.N, k % s.N, smg::Vector3<double>(1, 2, 3));
  });
  add("coincident frames", 6, 3507, [](Scene<double>& s) {  // no motion at all
    for (smg::Index k = s.N; k < s.T * s.N; ++k) s.set_pos(k / s.N, k % s.N, s.pos(0, k % s.N));
  });
  add("huge coordinates", 6, 3508, [](Scene<double>& s) { for (double& v : s.x) v *= 1e6; });
  add("tiny coordinates", 6, 3508, [](Scene<double>& s) { for (double& v : s.x) v *= 1e-6; });
  add("one frame", 1, 3509, [](Scene<double>&) {});
  add("two frames", 2, 3509, [](Scene<double>&) {});
  smg::test::every_operator([&](auto op) {
    using Op = decltype(op);
    for (const Case& c : cases) {
      CAPTURE(c.name);
      const Outputs<double> d = run_op<Op>(c.s, 2);
      CHECK(all_finite(d));
      CHECK(all_finite(run_op<Op>(c.s.cast<float>(), 2)));
      // A still trajectory (every frame the first, the rotations left as they are): an energy of
      // the positions alone has nothing to penalise (no acceleration, no velocity, no change
      // of any local offset), whatever the term, but for a constant floor an operator declares
      // (still_floor: sqrt_weighted's k sqrt(ε) per term). Those reading rotations see them change.
      if (c.name == "coincident frames" && Op::exact_gradient && !(Op::reads & smg::test::kReadsRotations)) {
        if (smg::test::still_floor<Op>())
          CHECK(d.energy > 0.0);
        else
          CHECK(d.energy == 0.0);
      }
      // ... and its gradient there is exactly 0, whatever the penalty (norm's sub-gradient at
      // 0, as torch's norm backward gives).
      if (c.name == "coincident frames" && Op::exact_gradient && !(Op::reads & smg::test::kReadsRotations))
        CHECK(std::all_of(d.gx.begin(), d.gx.end(), [](double v) { return v == 0.0; }));
    }
  });
}

TEST_CASE("every operator's validator takes good arguments and names a bad one") {
  namespace t = smg::test;
  const Scene<double> s = term_scene(6, 9, 3, 3510);
  const smg::Index T = s.T, N = s.N, K = s.K;
  const std::size_t TN = static_cast<std::size_t>(T * N);
  std::vector<double> gx(3 * TN), gr(3 * TN), c(TN), big(3 * (TN + N));
  const t::OperatorOutputs<double> out{{gx.data(), T, N}, {gr.data(), T, N}, {c.data(), T, N}};
  // Bad copies of each input: a NaN position, an out-of-range neighbour, a NaN confidence, a
  // visibility of 2, a zero quaternion.
  std::vector<double> x_nan = s.x, c_nan = s.c, q_zero = s.q;
  x_nan[3 * (2 * N + 4) + 1] = std::nan("");
  c_nan[static_cast<std::size_t>(3 * N + 2)] = std::nan("");
  for (int k = 0; k < 4; ++k) q_zero[static_cast<std::size_t>(4 * (N + 5) + k)] = 0.0;
  std::vector<std::int32_t> idx_bad = s.idx;
  idx_bad[static_cast<std::size_t>(4 * K + 1)] = static_cast<std::int32_t>(N);
  std::vector<std::uint8_t> v_bad = s.v;
  v_bad[7] = 2;
  const t::OperatorInputs<double> good = t::inputs_of(s, s.graph(), s.confidence());
  // Its message names the argument at its start ("positions: ...", "graph: ...").
  auto names = [](const smg::Status& st, const char* arg) {
    INFO(st.message());
    return !st && std::string(st.message()).rfind(arg, 0) == 0;
  };
  t::every_operator([&](auto op) {
    using Op = decltype(op);
    const smg::Status ok = Op::validate(good, out);
    CHECK_MESSAGE(ok, ok.message());
    t::OperatorInputs<double> in = good;
    if (!(Op::reads & t::kNoPositions)) {
      in.positions = {x_nan.data(), T, N};
      CHECK(names(Op::validate(in, out), "positions"));
    }
    if (Op::reads & t::kReadsGraph) {
      in = good;
      in.graph = {idx_bad.data(), s.w.data(), N, K};
      CHECK(names(Op::validate(in, out), "graph"));
    }
    if (Op::reads & t::kReadsConfidence) {
      in = good;
      in.confidence = {c_nan.data(), T, N};
      CHECK(names(Op::validate(in, out), "confidence"));
      in.confidence = {c.data(), T + 1, N};  // a wrong shape
      CHECK(names(Op::validate(in, out), "confidence"));
    }
    if (Op::reads & t::kReadsVisibility) {
      in = good;
      in.visibility = {v_bad.data(), T, N};
      CHECK(names(Op::validate(in, out), "visibility"));
    }
    if (Op::reads & t::kReadsRotations) {
      in = good;
      in.rotations = {q_zero.data(), T, N};
      CHECK(names(Op::validate(in, out), "rotations"));
    }
    // An output of the wrong shape, [T + 1][N]: whichever the operator writes.
    t::OperatorOutputs<double> bad = out;
    bad.positions = {big.data(), T + 1, N};
    bad.confidence = {big.data(), T + 1, N};
    bad.rotations = {big.data(), T + 1, N};
    const smg::Status st = Op::validate(good, bad);
    CHECK(!st);
    const std::string& m = st.message();
    CHECK((m.rfind("grad_positions", 0) == 0 || m.rfind("confidence", 0) == 0 ||
           m.rfind("grad_rotations", 0) == 0));
  });
}
