// tests/energy/operator_runs.hpp — one operator of the list (tests/support/operators.hpp) run on
// a test scene (tests/energy/scene.hpp), and the checks every such run shares: its outputs,
// their finiteness, bit-identity, and its gradient against central differences. Why a header:
// the tests over the whole list (tests/energy/test_terms.cpp, tests/stability/
// test_energy_hard_cases.cpp) run every operator the same way, so an operator added to the list
// reaches all of them through these few functions.
#pragma once

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "energy/scene.hpp"
#include "support/finite_diff.hpp"
#include "support/operators.hpp"

namespace smg::test {

// f(Op{}) for every operator of the list, with its name captured for the failure messages.
template <class F>
void every_operator(F&& f) {
  for_each_operator([&](auto op) {
    const std::string op_name = decltype(op)::name;  // doctest CAPTUREs a const char* as a pointer
    CAPTURE(op_name);
    f(op);
  });
}

// One operator's outputs on a scene: energy, position and rotation (tangent) gradients,
// confidences.
template <class S>
struct Outputs {
  double energy = 0;
  std::vector<S> gx, gr, c;
};

// Op::run on scene s (its graph and confidences unless given), on `threads` threads.
template <class Op, class S>
Outputs<S> run_op(const Scene<S>& s, int threads, EnergyWorkspace<S>* ws = nullptr) {
  Outputs<S> o;
  const std::size_t TN = static_cast<std::size_t>(s.T * s.N);
  o.gx.assign(3 * TN, S(0));
  o.gr.assign(3 * TN, S(0));
  o.c.assign(TN, S(0));
  ParallelOptions par;
  par.threads = threads;
  o.energy = static_cast<double>(Op::run(inputs_of(s, s.graph(), s.confidence()),
                                         OperatorOutputs<S>{{o.gx.data(), s.T, s.N},
                                                            {o.gr.data(), s.T, s.N},
                                                            {o.c.data(), s.T, s.N}},
                                         ws, par));
  return o;
}

// A random scene with confidences in [0, 1] and about a fifth of the nodes hidden per frame.
inline Scene<double> term_scene(Index T, Index N, Index K, unsigned seed) {
  Rng rng(seed);
  Scene<double> s = random_scene(T, N, K, rng);
  for (std::size_t k = 0; k < s.c.size(); ++k) {
    s.c[k] = rng.uniform(0.0, 1.0);
    s.v[k] = rng.uniform(0.0, 1.0) < 0.2 ? 0 : 1;
  }
  return s;
}

// The energy of Op at the scene's current values (gradients not computed).
template <class Op>
double energy_of(const Scene<double>& s) {
  ParallelOptions par;
  par.threads = 1;
  return static_cast<double>(Op::run(inputs_of(s, s.graph(), s.confidence()), OperatorOutputs<double>{},
                                     static_cast<EnergyWorkspace<double>*>(nullptr), par));
}

// Every output bit for bit.
template <class S>
bool same_bits(const Outputs<S>& a, const Outputs<S>& b) {
  return a.energy == b.energy && a.gx == b.gx && a.gr == b.gr && a.c == b.c;
}

template <class S>
bool all_finite(const Outputs<S>& o) {
  auto fin = [](const std::vector<S>& v) {
    return std::all_of(v.begin(), v.end(), [](S x) { return std::isfinite(x); });
  };
  return std::isfinite(o.energy) && fin(o.gx) && fin(o.gr) && fin(o.c);
}

template <class S>
bool all_zero(const std::vector<S>& v) {
  return std::all_of(v.begin(), v.end(), [](S x) { return x == S(0); });
}

// Checks Op's gradient on s against central differences of its energy with step h: the
// positions' within `tol` (relative), the rotations' along the right tangent within `tol` too,
// or exactly 0 where the differences are (an operator without rotations). s is restored.
template <class Op>
void check_gradient_fd(Scene<double>& s, double tol, double h = 1e-6) {
  const Outputs<double> a = run_op<Op>(s, 1);
  const std::vector<double> fx = central_gradient(s.x, [&] { return energy_of<Op>(s); }, h);
  CHECK(relative_error(a.gx, fx) < tol);
  std::vector<double> fr(a.gr.size());
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i) {
      const Eigen::Quaterniond q0 = s.rot(t, i);
      for (int c = 0; c < 3; ++c)
        fr[static_cast<std::size_t>((t * s.N + i) * 3 + c)] = central_difference_tangent(
            q0, c, [&](const Eigen::Quaterniond& q) { s.set_rot(t, i, q); }, [&] { return energy_of<Op>(s); }, h);
    }
  if (all_zero(fr))
    CHECK(all_zero(a.gr));
  else
    CHECK(relative_error(a.gr, fr) < tol);
}

}  // namespace smg::test
