// Hard cases of smg/energy, for every operator of the list (tests/support/operators.hpp): degenerate
// neighbourhoods (collinear, coincident, a single neighbour), zero-length edges, isolated nodes
// and empty rows, antipodal and near-180° rotations, T = 1 and 2, huge and tiny coordinates,
// gaps past the end, and NaN/Inf inputs and options refused by validation. Each has a defined
// behaviour (docs/math/energy.md, "Hard cases"). No term is named here: an operator added to the
// list gets every case with no edit of this file. The values a single term pins on these cases
// are that term's own tests (test_term_hard_cases.cpp).
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include "energy/operator_runs.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/operators.hpp"
#include "support/prelude.hpp"

using smg::test::every_operator;
using smg::test::Outputs;
using smg::test::run_op;
using smg::test::Scene;

namespace {

// Op's outputs on s in double, after checking that they are finite in double and in float.
template <class Op>
Outputs<double> finite_run(const Scene<double>& s) {
  const Outputs<double> d = run_op<Op>(s, 2);
  CHECK(smg::test::all_finite(d));
  CHECK(smg::test::all_finite(run_op<Op>(s.cast<float>(), 2)));
  return d;
}

// The scene with no edges: every row empty (-1, weight 0), or K = 0 columns.
Scene<double> without_edges(Scene<double> s, bool no_columns) {
  if (no_columns) {
    s.K = 0;
    s.idx.clear();
    s.w.clear();
  } else {
    std::fill(s.idx.begin(), s.idx.end(), -1);
    std::fill(s.w.begin(), s.w.end(), 0.0);
  }
  return s;
}

// Rotations whose relative rotations, between consecutive frames and between neighbours i and
// i + 1, are all near Exp(±θ a): node i at frame t is Exp(((t + i) mod 2) θ a) times a small
// random rotation.
Scene<double> half_turns(double theta, unsigned seed) {
  Scene<double> s = smg::test::term_scene(6, 8, 3, seed);
  Rng rng(seed + 1);
  const Vector3<double> a = Vector3<double>(0.3, -0.5, 0.8).normalized();
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i)
      s.set_rot(t, i,
                smg::so3::exp(Vector3<double>(double((t + i) % 2) * theta * a)) * smg::so3::exp(rng.vec3(0.01)));
  return s;
}

}  // namespace

TEST_CASE("every operator on degenerate neighbourhoods and zero-length edges: finite; exact gradients match central differences") {
  struct Case {
    const char* name;
    Scene<double> s;
    double tol, h;  // central differences: relative error and step; tol 0: not differentiated
  };
  std::vector<Case> cases;
  {
    SMG_TEST_RNG(rng, 801);
    const Vector3<double> dir = Vector3<double>(1, 2, -1).normalized();
    // Each neighbour moves along the line with a random acceleration: a trajectory of none
    // would put a norm penalty at its kink, where central differences do not apply.
    cases.push_back({"collinear", smg::test::star_scene(5, 6, rng, [&](Index t, Index k) {
                       return Vector3<double>((0.3 * double(k) + 0.05 * double(t * k % 3) + rng.uniform(-0.02, 0.02)) * dir +
                                              Vector3<double>(0.01 * double(t), 0, 0));
                     }), 1e-5, 1e-7});
  }
  {
    // Every neighbour at one point at t = 2. Not differentiated: an energy may be finite there
    // but not continuous (a fitted local motion pinned to 0 there, any spread lets it fit).
    SMG_TEST_RNG(rng, 802);
    const Vector3<double> p0(0.2, -0.1, 0.4);
    cases.push_back({"coincident", smg::test::star_scene(4, 5, rng, [&](Index t, Index k) {
                       return Vector3<double>(p0 + Vector3<double>(0.01 * double(t * (k + 1)), 0, 0) * (t == 2 ? 0.0 : 1.0));
                     }), 0.0, 0.0});
  }
  {
    Rng rng(803);
    cases.push_back({"single neighbour", smg::test::star_scene(4, 1, rng, [&](Index t, Index) {
                       return Vector3<double>(0.1 * double(t) + 0.03 * double(t * t), 0, 0);  // accelerating
                     }), 1e-6, 1e-6});
  }
  {
    // A neighbourhood of the two coincident nodes and a third is collinear: the collinear
    // case's tolerance.
    SMG_TEST_RNG(rng, 804);
    cases.push_back({"zero-length edges", smg::test::zero_length_edge_scene(rng), 1e-5, 1e-7});
  }
  for (Case& c : cases) {
    const std::string scene = c.name;  // doctest CAPTUREs a const char* as a pointer
    CAPTURE(scene);
    every_operator([&](auto op) {
      using Op = decltype(op);
      finite_run<Op>(c.s);
      if constexpr (Op::exact_gradient)
        if (c.tol > 0) smg::test::check_gradient_fd<Op>(c.s, c.tol, c.h);
    });
  }
}

TEST_CASE("every operator on isolated nodes and empty graphs: finite; no edges, no edge energy") {
  SMG_TEST_RNG(rng, 805);
  Scene<double> s = smg::test::random_scene(5, 8, 3, rng);
  smg::test::isolate_node(s, 3);
  const Scene<double> empty_rows = without_edges(s, false), no_columns = without_edges(s, true);
  every_operator([&](auto op) {
    using Op = decltype(op);
    finite_run<Op>(s);
    const Outputs<double> e = finite_run<Op>(empty_rows);
    // Empty rows and K = 0 columns are the same graph, whatever the operator.
    CHECK(smg::test::same_bits(e, run_op<Op>(no_columns, 2)));
    // An operator of edges alone has nothing left (its confidences, if any, are pinned values,
    // not an energy).
    if constexpr ((Op::reads & smg::test::kReadsGraph) != 0 && !smg::test::graph_free_terms<Op>()) {
      CHECK(e.energy == 0.0);
      CHECK(smg::test::all_zero(e.gx));
      CHECK(smg::test::all_zero(e.gr));
    }
  });
}

TEST_CASE("every operator with antipodal quaternions (q and -q): finite; the same outputs unless sign-sensitive") {
  const Scene<double> s = smg::test::term_scene(6, 8, 3, 810);
  Scene<double> flipped = s;
  for (Index t = 0; t < s.T; ++t)
    for (Index i = (t % 2); i < s.N; i += 2) flipped.set_rot(t, i, Quaternion<double>(-s.rot(t, i).coeffs()));
  every_operator([&](auto op) {
    using Op = decltype(op);
    const Outputs<double> a = run_op<Op>(s, 2), b = finite_run<Op>(flipped);
    if (smg::test::sign_sensitive<Op>()) return;  // a raw 4-vector comparison, by design
    CHECK(std::abs(a.energy - b.energy) <= 1e-12 * std::abs(a.energy));
    CHECK(smg::test::relative_error(b.gx, a.gx, 1e-12) < 1e-10);
    CHECK(smg::test::relative_error(b.gr, a.gr, 1e-12) < 1e-10);
    CHECK(b.c == a.c);
  });
}

TEST_CASE("every operator at near-180° relative rotations: finite; an exact gradient matches central differences") {
  const double pi = 3.14159265358979323846;
  for (const double theta : {pi, pi - 1e-6}) {
    CAPTURE(theta);
    const Scene<double> s = half_turns(theta, 811);
    every_operator([&](auto op) { finite_run<decltype(op)>(s); });
  }
  // Differentiated a little away from π, where the relative rotations' logarithm is smooth
  // (at π its sign flips).
  Scene<double> s = half_turns(pi - 0.2, 812);
  every_operator([&](auto op) {
    using Op = decltype(op);
    if constexpr (Op::exact_gradient) smg::test::check_gradient_fd<Op>(s, 1e-6);
  });
}

TEST_CASE("every operator on one and two frames: finite; one frame has no motion") {
  SMG_TEST_RNG(rng, 806);
  const Scene<double> one = smg::test::random_scene(1, 10, 4, rng);
  Scene<double> two = smg::test::random_scene(2, 7, 4, rng);
  every_operator([&](auto op) {
    using Op = decltype(op);
    const Outputs<double> a = finite_run<Op>(one);
    // No pair of frames: no velocity, acceleration or change of any offset, so no term at all
    // (a still_floor operator's floor is one per term).
    CHECK(a.energy == 0.0);
    // An operator that computes confidences (from the visibility): 1 where visible, else 0.
    if constexpr ((Op::reads & smg::test::kReadsVisibility) != 0)
      for (std::size_t k = 0; k < one.v.size(); ++k)
        CHECK(a.c[k] == (one.v[k] ? doctest::Approx(1.0) : doctest::Approx(0.0)));
    finite_run<Op>(two);
    if constexpr (Op::exact_gradient) smg::test::check_gradient_fd<Op>(two, 1e-7);
  });
}

TEST_CASE("every operator at huge and tiny coordinates: finite, float agrees with double") {
  SMG_TEST_RNG(rng, 807);
  const Scene<double> s = smg::test::random_scene(6, 30, 6, rng, true);
  for (double scale : {1e-6, 1e6}) {
    CAPTURE(scale);
    Scene<double> p = s;
    for (double& v : p.x) v *= scale;
    every_operator([&](auto op) {
      using Op = decltype(op);
      const Outputs<double> d = finite_run<Op>(p);
      const Outputs<float> f = run_op<Op>(p.cast<float>(), 2);
      CHECK(std::abs(f.energy - d.energy) <= 1e-3 * std::abs(d.energy));
    });
  }
}

TEST_CASE("every term with gaps: gaps past the end and zero gap weights add nothing") {
  const Scene<double> s = smg::test::term_scene(5, 8, 3, 808);
  const smg::test::OperatorInputs<double> in = smg::test::inputs_of(s, s.graph(), s.confidence());
  int terms_with_gaps = 0;
  every_operator([&](auto op) {
    using Op = decltype(op);
    if constexpr (Op::term != nullptr) {
      // Op's options with every gap list of its term set by `set`; whether the term has one.
      auto with_gaps = [&](const std::function<void(smg::GapList&)>& set, bool& has) {
        smg::RegularizerOptions o = Op::options();
        smg::for_each_term(o, [&](const char* term, bool, auto& opts) {
          if (std::string(term) != Op::term) return;
          smg::for_each_option(opts, [&](const char*, auto& field) {
            if constexpr (std::is_same<std::decay_t<decltype(field)>, smg::GapList>::value) {
              set(field);
              has = true;
            }
          });
        });
        return o;
      };
      auto run = [&](const smg::RegularizerOptions& o) {
        Outputs<double> r;
        r.gx.assign(s.x.size(), 0.0);
        r.gr.assign(s.x.size(), 0.0);
        r.c.assign(s.c.size(), 0.0);
        r.energy = double(Op::separate(in, o, {r.gx.data(), s.T, s.N}, smg::TangentsView<double>(r.gr.data(), s.T, s.N),
                                       {r.c.data(), s.T, s.N}, static_cast<smg::EnergyWorkspace<double>*>(nullptr),
                                       smg::ParallelOptions{}));
        return r;
      };
      bool has = false;
      const smg::RegularizerOptions past = with_gaps([&](smg::GapList& g) { g = {{static_cast<int>(s.T), 1.0}, {100, 1.0}, {1, 0.0}}; }, has);
      if (!has) return;
      ++terms_with_gaps;
      const Outputs<double> z = run(past);
      CHECK(z.energy == 0.0);
      CHECK(smg::test::all_zero(z.gx));
      CHECK(smg::test::all_zero(z.gr));
      // A gap past the end added to the defaults changes nothing, bit for bit.
      const smg::RegularizerOptions more = with_gaps([](smg::GapList& g) { g.push_back({100, 1.0}); }, has);
      CHECK(smg::test::same_bits(run(more), run(Op::options())));
    }
  });
  CHECK(terms_with_gaps > 0);  // the list has terms with gaps (else this case checks nothing)
}

TEST_CASE("every operator refuses NaN and Inf inputs, naming the argument and the element") {
  namespace t = smg::test;
  Rng rng(809);
  const Scene<double> s = smg::test::random_scene(3, 5, 2, rng);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> gx(s.x.size()), gr(s.x.size()), c(s.c.size());
  const t::OperatorOutputs<double> out{{gx.data(), s.T, s.N}, {gr.data(), s.T, s.N}, {c.data(), s.T, s.N}};
  // The message the operator's validator gives for scene b.
  auto message = [&](auto op, const Scene<double>& b) {
    return std::string(decltype(op)::validate(t::inputs_of(b, b.graph(), b.confidence()), out).message());
  };
  every_operator([&](auto op) {
    using Op = decltype(op);
    CHECK(message(op, s).empty());
    Scene<double> b = s;
    if constexpr ((Op::reads & t::kNoPositions) == 0) {
      b.x[4] = inf;
      CHECK(message(op, b) == "positions: element [t=0][i=1] is Inf");
      b.x[4] = nan;
      CHECK(message(op, b) == "positions: element [t=0][i=1] is NaN");
    }
    if constexpr ((Op::reads & t::kReadsRotations) != 0) {
      b = s;
      b.q[9] = nan;
      CHECK(message(op, b) == "rotations: element [t=0][i=2] is NaN");
    }
    if constexpr ((Op::reads & t::kReadsConfidence) != 0) {
      b = s;
      b.c[3] = nan;
      CHECK(message(op, b) == "confidence: element [t=0][i=3] is not in [0, 1]");
    }
    if constexpr ((Op::reads & t::kReadsGraph) != 0) {
      for (const double w : {nan, inf}) {
        b = s;
        b.w[0] = w;
        CHECK(message(op, b) == "graph: entry [i=0][k=0] has a weight that is negative or not finite");
      }
    }
  });
}

TEST_CASE("every term's operator refuses a NaN or Inf option value, naming the option") {
  namespace t = smg::test;
  Rng rng(809);
  const Scene<double> s = smg::test::random_scene(3, 5, 2, rng);
  std::vector<double> gx(s.x.size()), gr(s.x.size()), c(s.c.size());
  const t::OperatorOutputs<double> out{{gx.data(), s.T, s.N}, {gr.data(), s.T, s.N}, {c.data(), s.T, s.N}};
  const t::OperatorInputs<double> in = t::inputs_of(s, s.graph(), s.confidence());
  int refused = 0;
  every_operator([&](auto op) {
    using Op = decltype(op);
    if constexpr (Op::term != nullptr) {
      // Every number of the term's options (each double, each gap's weight) set to a bad value
      // by `set` in turn: refused, with the field's name in the message.
      auto each_bad = [&](double bad) {
        const smg::RegularizerOptions base = Op::options();
        std::vector<std::string> names;
        smg::for_each_term(base, [&](const char* term, bool, const auto& opts) {
          if (std::string(term) != Op::term) return;
          smg::for_each_option(opts, [&](const char* name, const auto& field) {
            using V = std::decay_t<decltype(field)>;
            if constexpr (std::is_same<V, double>::value || std::is_same<V, smg::GapList>::value)
              names.push_back(name);
          });
        });
        for (const std::string& name : names) {
          CAPTURE(name);
          smg::RegularizerOptions o = base;
          smg::for_each_term(o, [&](const char* term, bool, auto& opts) {
            if (std::string(term) != Op::term) return;
            smg::for_each_option(opts, [&](const char* n, auto& field) {
              using V = std::decay_t<decltype(field)>;
              if (name != n) return;
              if constexpr (std::is_same<V, double>::value) field = bad;
              if constexpr (std::is_same<V, smg::GapList>::value) field = {{1, bad}};
            });
          });
          const smg::Status st = Op::validate_with(in, out, o);
          CHECK(!st);
          CHECK(std::string(st.message()).find(name) != std::string::npos);
          ++refused;
        }
      };
      each_bad(std::numeric_limits<double>::quiet_NaN());
      each_bad(std::numeric_limits<double>::infinity());
    }
  });
  CHECK(refused > 0);
}
