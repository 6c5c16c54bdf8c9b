// Energies at a run-time size (default: the N = 5000 nodes, T = 100 frames, K = 16
// neighbours, gaps {1, 2, 4}); bench/notes/energy.md describes every row and counter.
// Parameters (flags or SMG_BENCH_* variables, bench/bench_common.hpp; --smg_help lists them):
//   --n --t --k --gaps=1,2,4 --threads=1,2 --precision=float|double|both --reps=3
//   --res_frames=10 (residual rows) --ad_frames=8 (autodiff rows, 0 = none) --locality=1
//
// Counters beside each time (wall time and process CPU time, bench_common.hpp):
//   ns_per_term         wall time per term: C-ARAP/ARAP one (edge, frame, gap) pair term, LRM one
//                       (edge, frame) neighbour entry, confidences one (edge, frame)
//   err_vs_double       float rows: ‖g_float − g_double‖ / ‖g_double‖ over the gradients the row
//                       computes (energy-only rows: relative energy error), where the double
//                       result is computed on the float-rounded inputs (identical inputs)
//   err_input_rounding  float rows: the same measure between double on the float-rounded inputs
//                       and double on the original inputs (what rounding the inputs alone costs)
//   err_detach_vs_exact LRM with ω held constant: ‖g_detached − g_exact‖ / ‖g_exact‖ (double)
//   ad_ratio            autodiff rows: AutoDiffScalar time / analytic time on the same problem
//   ns_per_block        residual rows: time per residual block (with its Jacobians)
//   separate_ns_per_term, speedup, fused_vs_separate, extra_mb, input_mb
//                       BM_regularizers: the four separate calls' time per term, separate / fused,
//                       the relative difference of their results, the fused step's workspace
//                       and the inputs' size (MB)
//   locality rows       C-ARAP / LRM with gradient with the nodes in a random order and in the
//                       Morton order of smg/graph/node_order.hpp (same scene, same graph)
//   floor_ms, x_floor   the row's floor on this machine, max(flops / peak, bytes / bandwidth) in
//                       ms, and the wall time per iteration over it (bench/floor.hpp: counts per
//                       case family, bench/notes/roofline.md; the peak of all cores, measured at
//                       start or read from bench_floor's JSON, --floor=FILE; --floor=off: none).
//                       Rows without a count (list/, residual and autodiff rows) have none.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <unsupported/Eigen/AutoDiff>

#include "energy/reference_energies.hpp"
#include "bench_common.hpp"
#include "floor.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "smg/graph/node_order.hpp"
#include "support/finite_diff.hpp"
#include "support/operators.hpp"

namespace {

using smg::Index;
using smg::Vector3;
using smg::test::Scene;

// The run-time configuration (main() fills it from the parameters before registering rows).
struct Config {
  Index N = 5000, T = 100, K = 16, res_frames = 10, ad_frames = 8;
  smg::GapList gaps = smg::default_gaps();
};
Config cfg;

const Scene<double>& scene() {
  // tests/energy/scene.hpp: rigid bodies with noise, K nearest neighbours, confidences.
  static const Scene<double> s = smg::test::rigid_bodies_scene(cfg.T, cfg.N, cfg.K);
  return s;
}
template <class S>
const Scene<S>& scene_as() {
  static const Scene<S> s = scene().cast<S>();
  return s;
}

// The scene with every input rounded to float and back: float and double rows on identical inputs.
const Scene<double>& rounded_scene() {
  static const Scene<double> s = scene_as<float>().template cast<double>();
  return s;
}

smg::CarapOptions carap_options() {  // gaps from the parameters, α 0.6, λc = λl = 1
  smg::CarapOptions o;
  o.gaps = cfg.gaps;
  return o;
}
smg::ArapOptions arap_options() {
  smg::ArapOptions o;
  o.gaps = cfg.gaps;
  return o;
}
smg::LrmOptions lrm_options(bool detach = false) {
  smg::LrmOptions o;
  o.detach_omega = detach;
  return o;
}

// Double-precision results, the references of the error columns.
struct Reference {
  double carap = 0, lrm = 0, lrm_detached = 0, arap = 0, accel = 0, conf_sum = 0;
  std::vector<double> carap_x, carap_r, lrm_x, lrm_detached_x, arap_x, arap_r, accel_x, conf;
};
Reference compute_reference(const Scene<double>& s) {
  {
    Reference f;
    const std::size_t n = s.x.size();
    f.carap_x.assign(n, 0.0);
    f.carap_r.assign(n, 0.0);
    f.lrm_x.assign(n, 0.0);
    f.lrm_detached_x.assign(n, 0.0);
    f.arap_x.assign(n, 0.0);
    f.arap_r.assign(n, 0.0);
    f.accel_x.assign(n, 0.0);
    f.conf.assign(s.v.size(), 0.0);
    smg::node_confidences<double>(s.positions(), s.visibility(), s.graph(), {},
                                  {f.conf.data(), s.T, s.N});
    f.carap = smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(),
                                 carap_options(), {f.carap_x.data(), s.T, s.N},
                                 {f.carap_r.data(), s.T, s.N});
    f.lrm = smg::lrm<double>(s.positions(), s.confidence(), s.graph(), lrm_options(),
                             {f.lrm_x.data(), s.T, s.N});
    f.lrm_detached = smg::lrm<double>(s.positions(), s.confidence(), s.graph(),
                                      lrm_options(true), {f.lrm_detached_x.data(), s.T, s.N});
    f.arap = smg::arap<double>(s.positions(), s.rotations(), s.graph(), arap_options(),
                               {f.arap_x.data(), s.T, s.N}, {f.arap_r.data(), s.T, s.N});
    f.accel = smg::accel<double>(s.positions(), {}, smg::AccelOptions{}, {f.accel_x.data(), s.T, s.N});
    return f;
  }
}
// Double on the float-rounded inputs: the reference of the float rows (identical inputs).
const Reference& reference() {
  static const Reference r = compute_reference(rounded_scene());
  return r;
}
// Double on the original inputs: reference() against it is the input-rounding error.
const Reference& original_reference() {
  static const Reference r = compute_reference(scene());
  return r;
}

// ‖a − b‖ / ‖b‖ (tests/support/finite_diff.hpp); over two gradients at once, positions and
// rotations, as one vector.
using smg::test::relative_error;
template <class A>
double relative_error(const std::vector<A>& a1, const std::vector<double>& b1, const std::vector<A>& a2,
                      const std::vector<double>& b2) {
  std::vector<A> a(a1);
  a.insert(a.end(), a2.begin(), a2.end());
  std::vector<double> b(b1);
  b.insert(b.end(), b2.begin(), b2.end());
  return relative_error(a, b);
}

smg::ParallelOptions threads(const benchmark::State& state) {
  smg::ParallelOptions p;
  p.threads = static_cast<int>(state.range(0));
  return p;
}
template <class S>
constexpr bool is_double() {
  return sizeof(S) == sizeof(double);
}

// Term counts of the per-term cost: E valid edges; C-ARAP/ARAP Σ_gaps (T − δ)·E pair terms, LRM
// and confidences T·E neighbour entries.
double edges() {
  const Scene<double>& s = scene();
  return static_cast<double>(std::count_if(s.idx.begin(), s.idx.end(), [](std::int32_t j) { return j >= 0; }));
}
double pair_terms() {
  double n = 0;
  for (const smg::Gap& g : cfg.gaps) n += static_cast<double>(std::max<Index>(0, cfg.T - g.delta));
  return n * edges();
}
double neighbour_terms() { return static_cast<double>(cfg.T) * edges(); }
void set_ns_per_term(benchmark::State& state, double seconds, double terms) {
  state.counters["ns_per_term"] = smg_bench::per(state, seconds, terms, 1e9);
}

// ---- the floor (bench/floor.hpp): the machine's peak, the shape of the scene as the counts take it
namespace rl = smg_bench::roofline;
rl::Machine machine;      // main() measures it or reads it (--floor)
bool floor_on = false;
double last_iteration_seconds = 0;  // time_energy's wall seconds per iteration
template <class S>
rl::Shape shape() {
  rl::Shape s;
  s.T = static_cast<double>(cfg.T);
  s.N = static_cast<double>(cfg.N);
  s.E = edges();
  s.pair_frames = pair_terms() / std::max(1.0, s.E);
  s.scalar = sizeof(S);
  s.index = sizeof(std::int32_t);
  s.vis = sizeof(std::uint8_t);
  s.rot_grad = 3;  // tangents
  return s;
}
// floor_ms and x_floor of a row whose work is `w` (the last time_energy's time per iteration).
template <class S>
void set_floor(benchmark::State& state, const rl::Work& w) {
  if (!floor_on) return;
  const double f = machine.floor_seconds(w, sizeof(S));
  state.counters["floor_ms"] = f * 1e3;
  state.counters["x_floor"] = f > 0 ? last_iteration_seconds / f : 0.0;
}

// The body every energy row shares: times `call()` (one evaluation, returning its energy), sets
// ns_per_term, and returns the energy of the last call.
template <class Call>
double time_energy(benchmark::State& state, double terms, Call&& call) {
  double e = 0;
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    e = call();
    benchmark::DoNotOptimize(e);
  }
  const double seconds = clock.seconds();
  last_iteration_seconds = smg_bench::per(state, seconds, 1.0, 1.0);
  set_ns_per_term(state, seconds, terms);
  return e;
}
// Float rows: err_vs_double = error(reference()) (double on the same, float-rounded, inputs) and
// err_input_rounding = rounding(reference(), original_reference()); double rows show 0 and nothing.
template <class S, class Error, class Rounding>
void set_errors(benchmark::State& state, Error&& error, Rounding&& rounding) {
  state.counters["err_vs_double"] = is_double<S>() ? 0.0 : error(reference());
  if (!is_double<S>()) state.counters["err_input_rounding"] = rounding(reference(), original_reference());
}
// The gradient views of a row: `on` = false gives empty views (energy-only rows).
template <class S>
smg::PositionsView<S> grad_view(std::vector<S>& g, const Scene<S>& s, bool on) {
  if (on) std::fill(g.begin(), g.end(), S(0));
  return on ? smg::PositionsView<S>(g.data(), s.T, s.N) : smg::PositionsView<S>();
}
template <class S>
smg::TangentsView<S> tangent_view(std::vector<S>& g, const Scene<S>& s, bool on) {
  if (on) std::fill(g.begin(), g.end(), S(0));
  return on ? smg::TangentsView<S>(g.data(), s.T, s.N) : smg::TangentsView<S>();
}

// ---- confidences ----
template <class S>
void BM_confidence(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> c(s.v.size());
  smg::EnergyWorkspace<S> ws;
  time_energy(state, neighbour_terms(), [&] {
    smg::node_confidences<S>(s.positions(), s.visibility(), s.graph(), {}, {c.data(), s.T, s.N},
                             {}, {}, &ws, threads(state));
    return double(c[0]);
  });
  set_floor<S>(state, rl::confidences(shape<S>()));
  set_errors<S>(
      state, [&](const Reference& r) { return relative_error(c, r.conf); },
      [](const Reference& r, const Reference& o) { return relative_error(r.conf, o.conf); });
}

// ---- C-ARAP and plain ARAP (kGradient: energy and gradients w.r.t. positions and rotations) ----
// One row each; kCarap picks the energy, its double results are the references.
template <bool kCarap>
double ref_energy(const Reference& r) {
  return kCarap ? r.carap : r.arap;
}
template <bool kCarap>
const std::vector<double>& ref_x(const Reference& r) {
  return kCarap ? r.carap_x : r.arap_x;
}
template <bool kCarap>
const std::vector<double>& ref_r(const Reference& r) {
  return kCarap ? r.carap_r : r.arap_r;
}
template <class S, bool kGradient, bool kCarap>
void rigidity_row(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size()), gr(s.x.size());
  smg::EnergyWorkspace<S> ws;
  const double e = time_energy(state, pair_terms(), [&] {
    const smg::PositionsView<S> vx = grad_view(gx, s, kGradient);
    const smg::TangentsView<S> vr = tangent_view(gr, s, kGradient);
    if constexpr (kCarap)
      return double(smg::carap<S>(s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(), vx,
                                  vr, &ws, threads(state)));
    else
      return double(smg::arap<S>(s.positions(), s.rotations(), s.graph(), arap_options(), vx, vr, &ws,
                                 threads(state)));
  });
  set_floor<S>(state, rl::rigidity(shape<S>(), kCarap, kGradient));
  set_errors<S>(
      state,
      [&](const Reference& r) {
        return kGradient ? relative_error(gx, ref_x<kCarap>(r), gr, ref_r<kCarap>(r))
                         : std::abs(e - ref_energy<kCarap>(r)) / ref_energy<kCarap>(r);
      },
      [](const Reference& r, const Reference& o) {
        return kGradient ? relative_error(ref_x<kCarap>(r), ref_x<kCarap>(o), ref_r<kCarap>(r), ref_r<kCarap>(o))
                         : std::abs(ref_energy<kCarap>(r) - ref_energy<kCarap>(o)) / ref_energy<kCarap>(o);
      });
}
template <class S, bool kGradient>
void BM_carap(benchmark::State& state) {
  rigidity_row<S, kGradient, true>(state);
}
template <class S, bool kGradient>
void BM_arap(benchmark::State& state) {
  rigidity_row<S, kGradient, false>(state);
}

// ---- LRM: 0 energy only, 1 exact gradient, 2 gradient with ω held constant ----
template <int kMode>
const std::vector<double>& lrm_ref_x(const Reference& r) {
  return kMode == 1 ? r.lrm_x : r.lrm_detached_x;
}
template <class S, int kMode>
void BM_lrm(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size());
  smg::EnergyWorkspace<S> ws;
  const double e = time_energy(state, neighbour_terms(), [&] {
    return double(smg::lrm<S>(s.positions(), s.confidence(), s.graph(), lrm_options(kMode == 2),
                              grad_view(gx, s, kMode > 0), &ws, threads(state)));
  });
  set_floor<S>(state, rl::lrm(shape<S>(), kMode));
  set_errors<S>(
      state,
      [&](const Reference& r) {
        return kMode == 0 ? std::abs(e - r.lrm) / r.lrm : relative_error(gx, lrm_ref_x<kMode>(r));
      },
      [](const Reference& r, const Reference& o) {
        return kMode == 0 ? std::abs(r.lrm - o.lrm) / o.lrm : relative_error(lrm_ref_x<kMode>(r), lrm_ref_x<kMode>(o));
      });
  if (kMode == 2)
    state.counters["err_detach_vs_exact"] = relative_error(original_reference().lrm_detached_x, original_reference().lrm_x);
}

// ---- Trajectory smoothness (E21), acceleration form, unweighted: energy + position gradient;
// ns_per_term over the (T − 2)·N second differences ----
template <class S>
void BM_accel(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size());
  smg::EnergyWorkspace<S> ws;
  const double terms = static_cast<double>(std::max<Index>(0, cfg.T - 2)) * static_cast<double>(cfg.N);
  time_energy(state, terms, [&] {
    return double(smg::accel<S>(s.positions(), {}, smg::AccelOptions{}, grad_view(gx, s, true), &ws,
                                threads(state)));
  });
  set_floor<S>(state, rl::accel(shape<S>()));
  set_errors<S>(
      state, [&](const Reference& r) { return relative_error(gx, r.accel_x); },
      [](const Reference& r, const Reference& o) { return relative_error(r.accel_x, o.accel_x); });
}

// ---- Every operator of the cross-cutting tests' list (tests/support/operators.hpp), with the
// list's options, energy and every output it writes: list/<name><S>. A term added to the list
// gets its row here with no code of its own. ns_per_term is per (frame, node); err_vs_double
// (float rows) compares the outputs and energy with the double call on the same rounded inputs ----
template <class Op, class S>
double listed_run(const Scene<S>& s, smg::EnergyWorkspace<S>& ws, std::vector<S>& gx, std::vector<S>& gr,
                  std::vector<S>& c, smg::ParallelOptions par) {
  const smg::test::OperatorOutputs<S> out{grad_view(gx, s, true), tangent_view(gr, s, true),
                                          {c.data(), s.T, s.N}};
  return double(Op::run(smg::test::inputs_of(s, s.graph(), s.confidence()), out, &ws, par));
}
// A row's outputs and energy, as one vector of doubles (what err_vs_double compares).
template <class S>
std::vector<double> listed_outputs(const std::vector<S>& gx, const std::vector<S>& gr,
                                   const std::vector<S>& c, double e) {
  std::vector<double> all(gx.begin(), gx.end());
  all.insert(all.end(), gr.begin(), gr.end());
  all.insert(all.end(), c.begin(), c.end());
  all.push_back(e);
  return all;
}
template <class Op, class S>
void BM_listed(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size()), gr(s.x.size()), c(s.x.size() / 3);
  smg::EnergyWorkspace<S> ws;
  double e = 0;
  time_energy(state, static_cast<double>(cfg.T) * static_cast<double>(cfg.N), [&] {
    e = listed_run<Op>(s, ws, gx, gr, c, threads(state));
    return e;
  });
  if (is_double<S>()) return;
  const Scene<double>& r = rounded_scene();
  std::vector<double> rx(r.x.size()), rr(r.x.size()), rc(r.x.size() / 3);
  smg::EnergyWorkspace<double> rws;
  const double re = listed_run<Op>(r, rws, rx, rr, rc, {});
  state.counters["err_vs_double"] =
      relative_error(listed_outputs(gx, gr, c, e), listed_outputs(rx, rr, rc, re));
}

// ---- The target: C-ARAP + LRM, energy + exact gradient, into one gradient buffer ----
template <class S>
void BM_carap_plus_lrm(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size()), gr(s.x.size());
  smg::EnergyWorkspace<S> ws;
  time_energy(state, pair_terms() + neighbour_terms(), [&] {
    const smg::PositionsView<S> g = grad_view(gx, s, true);
    return double(smg::carap<S>(s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(), g,
                                tangent_view(gr, s, true), &ws, threads(state))) +
           double(smg::lrm<S>(s.positions(), s.confidence(), s.graph(), lrm_options(), g, &ws, threads(state)));
  });
  set_floor<S>(state, rl::carap_plus_lrm(shape<S>()));
  auto sum = [](const Reference& r) {
    std::vector<double> v(r.carap_x.size());
    for (std::size_t k = 0; k < v.size(); ++k) v[k] = r.carap_x[k] + r.lrm_x[k];
    return v;
  };
  set_errors<S>(
      state, [&](const Reference& r) { return relative_error(gx, sum(r), gr, r.carap_r); },
      [&](const Reference& r, const Reference& o) { return relative_error(sum(r), sum(o), r.carap_r, o.carap_r); });
  state.counters["target_ms"] = 100.0;
}

// ---- The fused regulariser step (smg/energy/regularizers.hpp): confidences + C-ARAP + ARAP +
// LRM in one pass, against the four separate calls on the same scene, threads and workspace
// reuse. ns_per_term is the fused step's; separate_ns_per_term the separate calls' (timed right
// after, the same number of iterations), speedup their ratio, extra_mb the fused step's
// workspace and input_mb the inputs it stays under. ----
smg::RegularizerOptions regularizer_options() {
  smg::RegularizerOptions o;
  o.terms.arap = true;
  o.carap = carap_options();
  o.arap = arap_options();
  o.lrm = lrm_options();
  return o;
}
template <class S, bool kGradient>
void BM_regularizers(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  const smg::RegularizerOptions o = regularizer_options();
  std::vector<S> gx(s.x.size()), gr(s.x.size()), c(s.v.size());
  smg::EnergyWorkspace<S> ws, ws_sep;
  const double terms = 2 * neighbour_terms() + 2 * pair_terms();
  const smg::FrameScalarsView<S> cv(c.data(), s.T, s.N);
  auto fused = [&] {
    return double(smg::regularizers<S>(s.positions(), s.rotations(), s.visibility(), s.graph(), o, cv,
                                       grad_view(gx, s, kGradient), tangent_view(gr, s, kGradient),
                                       &ws, threads(state))
                      .total());
  };
  auto separate = [&] {
    const smg::PositionsView<S> vx = grad_view(gx, s, kGradient);
    const smg::TangentsView<S> vr = tangent_view(gr, s, kGradient);
    smg::node_confidences<S>(s.positions(), s.visibility(), s.graph(), o.confidence, cv, {}, {}, &ws_sep,
                             threads(state));
    const smg::FrameScalarsView<const S> cc(c.data(), s.T, s.N);
    return double(smg::carap<S>(s.positions(), s.rotations(), cc, s.graph(), o.carap, vx, vr, &ws_sep,
                                threads(state))) +
           double(smg::arap<S>(s.positions(), s.rotations(), s.graph(), o.arap, vx, vr, &ws_sep, threads(state))) +
           double(smg::lrm<S>(s.positions(), cc, s.graph(), o.lrm, vx, &ws_sep, threads(state)));
  };
  const double e = time_energy(state, terms, fused);
  set_floor<S>(state, rl::step(shape<S>(), kGradient));  // the fused step's time, not the separate calls'
  const std::vector<S> fgx = gx, fgr = gr;
  const double fused_ns = state.counters["ns_per_term"];
  double e_sep = 0;
  const smg_bench::Stopwatch clock;
  const Index iters = std::max<Index>(1, static_cast<Index>(state.iterations()));
  for (Index k = 0; k < iters; ++k) {
    e_sep = separate();
    benchmark::DoNotOptimize(e_sep);
  }
  const double sep_ns = clock.seconds() * 1e9 / (static_cast<double>(iters) * terms);
  state.counters["separate_ns_per_term"] = sep_ns;
  state.counters["speedup"] = fused_ns > 0 ? sep_ns / fused_ns : 0.0;
  state.counters["fused_vs_separate"] =
      kGradient ? relative_error(fgx, std::vector<double>(gx.begin(), gx.end()), fgr,
                                 std::vector<double>(gr.begin(), gr.end()))
                : std::abs(e - e_sep) / std::abs(e_sep);
  state.counters["extra_mb"] = static_cast<double>(ws.bytes()) / 1e6;
  state.counters["input_mb"] =
      static_cast<double>(sizeof(S) * (s.x.size() + s.q.size() + s.w.size()) + s.v.size() +
                          sizeof(std::int32_t) * s.idx.size()) / 1e6;
  auto total = [](const Reference& r, bool x) {
    std::vector<double> v(r.carap_x.size());
    for (std::size_t k = 0; k < v.size(); ++k)
      v[k] = x ? r.carap_x[k] + r.arap_x[k] + r.lrm_x[k] : r.carap_r[k] + r.arap_r[k];
    return v;
  };
  set_errors<S>(
      state,
      [&](const Reference& r) {
        return kGradient ? relative_error(fgx, total(r, true), fgr, total(r, false))
                         : std::abs(e - (r.carap + r.arap + r.lrm)) / (r.carap + r.arap + r.lrm);
      },
      [&](const Reference& r, const Reference& q) {
        return kGradient ? relative_error(total(r, true), total(q, true), total(r, false), total(q, false))
                         : std::abs((r.carap + r.arap + r.lrm) - (q.carap + q.arap + q.lrm)) /
                               (q.carap + q.arap + q.lrm);
      });
}

// ---- Memory locality: the same scene and graph with the nodes in a random order, and in the
// Morton order of smg/graph/node_order.hpp computed from that random order. ----
const Scene<double>& reordered_scene(const smg::NodeOrder& order) {
  static Scene<double> r;
  const Scene<double>& s = scene();
  r = s;
  smg::reorder_nodes(order, s.positions(), smg::PositionsView<double>(r.x.data(), s.T, s.N));
  smg::reorder_nodes(order, s.rotations(), smg::QuaternionsView<double>(r.q.data(), s.T, s.N));
  smg::reorder_nodes(order, s.visibility(), smg::VisibilityView<std::uint8_t>(r.v.data(), s.T, s.N));
  smg::reorder_nodes(order, s.confidence(), smg::FrameScalarsView<double>(r.c.data(), s.T, s.N));
  smg::reorder_graph(order, s.graph(), {r.idx.data(), s.N, s.K}, {r.w.data(), s.N, s.K});
  return r;
}
smg::NodeOrder random_order() {
  std::vector<Index> p(static_cast<std::size_t>(cfg.N));
  std::iota(p.begin(), p.end(), Index(0));
  std::mt19937_64 g(99);
  std::shuffle(p.begin(), p.end(), g);
  return smg::NodeOrder::from_new_to_old(p);
}
// kMorton = false: random order; true: Morton order (of the randomly ordered scene).
template <class S, bool kMorton>
const Scene<S>& ordered_scene() {
  static const Scene<S> s = [] {
    const Scene<double> random = reordered_scene(random_order());
    if (!kMorton) return random.cast<S>();
    const smg::NodeOrder order = smg::spatial_node_order(random.positions(), random.visibility());
    Scene<double> sorted = random;
    smg::reorder_nodes(order, random.positions(), smg::PositionsView<double>(sorted.x.data(), random.T, random.N));
    smg::reorder_nodes(order, random.rotations(), smg::QuaternionsView<double>(sorted.q.data(), random.T, random.N));
    smg::reorder_nodes(order, random.visibility(), smg::VisibilityView<std::uint8_t>(sorted.v.data(), random.T, random.N));
    smg::reorder_nodes(order, random.confidence(), smg::FrameScalarsView<double>(sorted.c.data(), random.T, random.N));
    smg::reorder_graph(order, random.graph(), {sorted.idx.data(), random.N, random.K},
                       {sorted.w.data(), random.N, random.K});
    return sorted.cast<S>();
  }();
  return s;
}
// Mean |i − j| over the graph's edges: how far apart in memory neighbours are stored.
template <class S>
double mean_edge_span(const Scene<S>& s) {
  double sum = 0, n = 0;
  for (Index i = 0; i < s.N; ++i)
    for (Index k = 0; k < s.K; ++k) {
      const std::int32_t j = s.idx[static_cast<std::size_t>(i * s.K + k)];
      if (j < 0) continue;
      sum += std::abs(static_cast<double>(j - i));
      n += 1;
    }
  return sum / std::max(1.0, n);
}
// kEnergy 0: C-ARAP + gradient; 1: LRM + exact gradient.
template <class S, int kEnergy, bool kMorton>
void BM_locality(benchmark::State& state) {
  const Scene<S>& s = ordered_scene<S, kMorton>();
  std::vector<S> gx(s.x.size()), gr(s.x.size());
  smg::EnergyWorkspace<S> ws;
  const double e = time_energy(state, kEnergy == 0 ? pair_terms() : neighbour_terms(), [&] {
    if constexpr (kEnergy == 0)
      return double(smg::carap<S>(s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(),
                                  grad_view(gx, s, true), tangent_view(gr, s, true), &ws, threads(state)));
    else
      return double(smg::lrm<S>(s.positions(), s.confidence(), s.graph(), lrm_options(), grad_view(gx, s, true),
                                &ws, threads(state)));
  });
  set_floor<S>(state, kEnergy == 0 ? rl::rigidity(shape<S>(), true, true) : rl::lrm(shape<S>(), 1));
  // The energy does not depend on the order: its relative difference to the input order's.
  const Reference& r = is_double<S>() ? original_reference() : reference();
  const double ref = kEnergy == 0 ? r.carap : r.lrm;
  state.counters["energy_vs_input_order"] = std::abs(e - ref) / ref;
  state.counters["mean_edge_span"] = mean_edge_span(s);
}

// ---- Residual + Jacobian forms, streamed through a visitor that forms 2 Jᵀ r per chunk-free
// sum (the sum of squares, so nothing is optimised away). Run on the first res_frames frames:
// the per-block cost does not depend on T. ----
// The scene's first `frames` frames.
Scene<double> first_frames(Index frames) {
  Scene<double> r = scene();
  r.resize(std::min(frames, r.T), r.N);
  return r;
}
template <class S>
const Scene<S>& residual_scene() {
  static const Scene<S> s = first_frames(cfg.res_frames).cast<S>();
  return s;
}
// ns_per_block: wall time per residual block.
void set_ns_per_block(benchmark::State& state, double seconds, double blocks) {
  state.counters["ns_per_block"] = smg_bench::per(state, seconds, blocks, 1e9);
}
template <class S>
void BM_carap_residuals(benchmark::State& state) {
  const Scene<S>& s = residual_scene<S>();
  const auto par = threads(state);
  const Index chunks = smg::carap_residual_chunks(s.T, s.N, carap_options().gaps.size());
  // One partial per chunk, 16 doubles apart (no false sharing between threads).
  constexpr std::size_t kPad = 16;
  std::vector<double> partial(static_cast<std::size_t>(chunks) * kPad);
  Index blocks = 0;
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    std::fill(partial.begin(), partial.end(), 0.0);
    smg::for_each_carap_residual<S>(
        s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(),
        [&](const smg::CarapResidualBlock<S>& b, Index chunk) {
          partial[static_cast<std::size_t>(chunk) * kPad] +=
              double(b.r.squaredNorm()) + double((b.J_xj_s.transpose() * b.r).sum()) +
              double((b.J_rot_i_t.transpose() * b.r).sum());
        },
        true, par);
    benchmark::DoNotOptimize(partial.data());
  }
  const double seconds = clock.seconds();
  blocks = smg::carap_residual_count(s.graph(), s.T, carap_options());
  set_ns_per_block(state, seconds, static_cast<double>(blocks));
}
template <class S>
void BM_lrm_residuals(benchmark::State& state) {
  const Scene<S>& s = residual_scene<S>();
  const auto par = threads(state);
  constexpr std::size_t kPad = 16;  // no false sharing between threads
  std::vector<double> partial(static_cast<std::size_t>(smg::lrm_residual_chunks(s.T, s.N)) * kPad);
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    std::fill(partial.begin(), partial.end(), 0.0);
    smg::for_each_lrm_residual<S>(
        s.positions(), s.confidence(), s.graph(), lrm_options(),
        [&](const smg::LrmResidualBlock<S>& b, Index chunk) {
          partial[static_cast<std::size_t>(chunk) * kPad] +=
              double(b.r.squaredNorm()) + double((b.J_x.transpose() * b.r).sum());
        },
        true, par);
    benchmark::DoNotOptimize(partial.data());
  }
  set_ns_per_block(state, clock.seconds(), static_cast<double>(s.T * s.N));
}

// ---- Eigen AutoDiffScalar, per term (the fair comparison): each C-ARAP pair term with an
// 18-entry fixed-size derivative vector (x_i, x_j at both frames, the two right tangents of
// R_i), each LRM neighbourhood with a derivative vector of 6·|N(i)| <= 96 entries (x_j and u_j
// of every neighbour, then u chained to x). Same equations, written straight from docs/design.md in
// tests/energy/reference_energies.hpp. Double, one thread, on the first ad_frames frames; the
// analytic kernel is timed on the same sub-problem for ad_ratio. ----
const Scene<double>& ad_scene() {
  static const Scene<double> s = first_frames(cfg.ad_frames);
  return s;
}
template <class F>
double seconds_of(F&& f, int reps) {
  double best = 1e300;
  for (int k = 0; k < reps; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return best;
}

using AD18 = Eigen::AutoDiffScalar<Eigen::Matrix<double, 18, 1>>;
void carap_autodiff(const Scene<double>& s, std::vector<double>& gx, std::vector<double>& gr) {
  const smg::CarapOptions o = carap_options();
  std::fill(gx.begin(), gx.end(), 0.0);
  std::fill(gr.begin(), gr.end(), 0.0);
  auto var3 = [](const Vector3<double>& v, int off) {
    Vector3<AD18> a;
    for (int c = 0; c < 3; ++c) a(c) = AD18(v(c), 18, off + c);
    return a;
  };
  auto rot = [](const smg::Quaternion<double>& q, int off) {
    Vector3<AD18> phi;
    for (int c = 0; c < 3; ++c) phi(c) = AD18(0.0, 18, off + c);
    const smg::Quaternion<AD18> qa = q.normalized().cast<AD18>() * smg::so3::exp(phi);
    return smg::Matrix3<AD18>(qa.toRotationMatrix());
  };
  for (const smg::Gap& g : o.gaps)
    for (Index t = 0; t + g.delta < s.T; ++t)
      for (Index i = 0; i < s.N; ++i)
        for (Index k = 0; k < s.K; ++k) {
          const Index j = s.idx[i * s.K + k], u = t + g.delta;
          if (j < 0) break;
          const double w = g.weight * s.w[i * s.K + k] *
                           (o.alpha + (1 - o.alpha) * s.c[t * s.N + j]);
          const AD18 e = smg::test::ref::carap_pair<AD18>(
              var3(s.pos(t, i), 0), var3(s.pos(t, j), 3), rot(s.rot(t, i), 12),
              var3(s.pos(u, i), 6), var3(s.pos(u, j), 9), rot(s.rot(u, i), 15), w, o.lambda_c,
              o.lambda_l);
          const auto& d = e.derivatives();
          for (int c = 0; c < 3; ++c) {
            gx[(t * s.N + i) * 3 + c] += d(c);
            gx[(t * s.N + j) * 3 + c] += d(3 + c);
            gx[(u * s.N + i) * 3 + c] += d(6 + c);
            gx[(u * s.N + j) * 3 + c] += d(9 + c);
            gr[(t * s.N + i) * 3 + c] += d(12 + c);
            gr[(u * s.N + i) * 3 + c] += d(15 + c);
          }
        }
}

using ADN = Eigen::AutoDiffScalar<Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 96, 1>>;
void lrm_autodiff(const Scene<double>& s, std::vector<double>& gx) {
  const smg::LrmOptions o = lrm_options();
  std::fill(gx.begin(), gx.end(), 0.0);
  const auto X = smg::test::ref::positions_of<double>(s);
  for (Index t = 0; t < s.T; ++t) {
    const smg::VelocityFrames vf = smg::velocity_frames(t, s.T);
    for (Index i = 0; i < s.N; ++i) {
      Index n = 0;
      while (n < s.K && s.idx[i * s.K + n] >= 0) ++n;
      const int nv = static_cast<int>(6 * n);
      std::vector<Vector3<ADN>> x(static_cast<std::size_t>(n)), u(static_cast<std::size_t>(n));
      std::vector<double> a(static_cast<std::size_t>(n));
      for (Index k = 0; k < n; ++k) {
        const Index j = s.idx[i * s.K + k];
        const Vector3<double> uj = smg::test::ref::velocity(X, s.T, s.N, t, j);
        for (int c = 0; c < 3; ++c) {
          x[k](c) = ADN(X[t * s.N + j](c), nv, static_cast<int>(3 * k + c));
          u[k](c) = ADN(uj(c), nv, static_cast<int>(3 * (n + k) + c));
        }
        a[k] = s.w[i * s.K + k] * (o.alpha + (1 - o.alpha) * s.c[t * s.N + j]);
      }
      const ADN e = smg::test::ref::lrm_neighbourhood<ADN>(x, u, a, o.huber_delta, 1e-10, false);
      if (e.derivatives().size() != nv) continue;
      for (Index k = 0; k < n; ++k) {
        const Index j = s.idx[i * s.K + k];
        for (int c = 0; c < 3; ++c) {
          const double dx = e.derivatives()(3 * k + c), du = e.derivatives()(3 * (n + k) + c);
          gx[(t * s.N + j) * 3 + c] += dx;
          if (vf.moving) {
            gx[(vf.plus * s.N + j) * 3 + c] += du;
            gx[(vf.minus * s.N + j) * 3 + c] -= du;
          }
        }
      }
    }
  }
}

// An autodiff row: times autodiff() (AutoDiffScalar gradients into gx), then ad_ratio against
// analytic(one_thread, ws), the analytic kernel on the same sub-problem (best of 5).
template <class AutoDiff, class Analytic>
void autodiff_row(benchmark::State& state, const std::vector<double>& gx, AutoDiff&& autodiff,
                  Analytic&& analytic) {
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    autodiff();
    benchmark::DoNotOptimize(gx.data());
  }
  const double ad = clock.seconds() / static_cast<double>(std::max<benchmark::IterationCount>(1, state.iterations()));
  smg::ParallelOptions one;
  one.threads = 1;
  smg::EnergyWorkspace<double> ws;
  const double analytic_seconds = seconds_of([&] { analytic(one, ws); }, 5);
  state.counters["ad_ratio"] = ad / analytic_seconds;
}
void BM_autodiff_carap(benchmark::State& state) {
  const Scene<double>& s = ad_scene();
  std::vector<double> gx(s.x.size()), gr(s.x.size());
  std::vector<double> ax(s.x.size(), 0.0), ar(s.x.size(), 0.0);
  autodiff_row(
      state, gx, [&] { carap_autodiff(s, gx, gr); },
      [&](smg::ParallelOptions one, smg::EnergyWorkspace<double>& ws) {
        std::fill(ax.begin(), ax.end(), 0.0);
        std::fill(ar.begin(), ar.end(), 0.0);
        smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(),
                           {ax.data(), s.T, s.N}, {ar.data(), s.T, s.N}, &ws, one);
      });
  state.counters["err_vs_analytic"] = relative_error(gx, ax, gr, ar);
}
void BM_autodiff_lrm(benchmark::State& state) {
  const Scene<double>& s = ad_scene();
  std::vector<double> gx(s.x.size());
  std::vector<double> ax(s.x.size(), 0.0);
  autodiff_row(
      state, gx, [&] { lrm_autodiff(s, gx); },
      [&](smg::ParallelOptions one, smg::EnergyWorkspace<double>& ws) {
        std::fill(ax.begin(), ax.end(), 0.0);
        smg::lrm<double>(s.positions(), s.confidence(), s.graph(), lrm_options(), {ax.data(), s.T, s.N}, &ws,
                         one);
      });
  state.counters["err_vs_analytic"] = relative_error(gx, ax);
}

}  // namespace

int main(int argc, char** argv) {
  smg_bench::Params p(argc, argv, "energy");
  cfg.N = p.integer("n", 5000, "nodes N");
  cfg.T = p.integer("t", 100, "frames T");
  cfg.K = p.integer("k", 16, "neighbours K (KNN graph on frame 0)");
  const std::vector<long> gaps = p.list("gaps", {1, 2, 4}, "C-ARAP / ARAP frame gaps, weight 1 each");
  const std::vector<long> thread_counts = p.list("threads", {1, 2}, "ParallelOptions::threads of every row");
  p.precision();
  const int reps = p.reps(3);
  cfg.res_frames = p.integer("res_frames", 10, "frames of the residual rows");
  cfg.ad_frames = p.integer("ad_frames", 8, "frames of the AutoDiffScalar rows (0: no autodiff rows)");
  const bool locality = p.integer("locality", 1, "1: the random-vs-Morton node order rows") != 0;
  const std::string floor = p.text("floor", "measure",
                                   "measure | off | FILE (bench_floor --json=FILE): the peak behind floor_ms, x_floor");
  p.finish();
  if (cfg.N < 2 || cfg.T < 2 || cfg.K < 1) {
    std::fprintf(stderr, "bench_energy: need n >= 2, t >= 2, k >= 1\n");
    return 2;
  }
  cfg.gaps = smg::GapList();
  for (long g : gaps) cfg.gaps.push_back({static_cast<int>(g), 1.0});
  if (!smg::validate_options(carap_options())) {
    std::fprintf(stderr, "bench_energy: invalid gaps: %s\n", smg::validate_options(carap_options()).message().c_str());
    return 2;
  }

  if (floor != "off") {
    bool ok = true;
    machine = floor == "measure" ? rl::measure_machine() : rl::load_machine(floor, ok);
    if (!ok) {
      std::fprintf(stderr, "bench_energy: --floor=%s: not a bench_floor JSON file\n", floor.c_str());
      return 2;
    }
    floor_on = true;
    char b[256];
    std::snprintf(b, sizeof b, "FP32 %.1f GFLOP/s (%s), FP64 %.1f GFLOP/s, %.1f GB/s, %d threads (%s)",
                  machine.fp32_gflops, machine.best_isa.c_str(), machine.fp64_gflops, machine.bandwidth_gbs,
                  machine.threads, floor == "measure" ? "measured at start" : floor.c_str());
    benchmark::AddCustomContext("floor_machine", b);
  }
  // One row per thread count, named like BENCHMARK_TEMPLATE's "BM_x<float, true>/threads:2".
  auto add = [&](const std::string& name, void (*f)(benchmark::State&)) {
    auto* b = benchmark::RegisterBenchmark(name.c_str(), f);
    b->ArgName("threads")->Unit(benchmark::kMillisecond);
    for (long t : thread_counts) b->Arg(t);
    smg_bench::protocol(b, reps);
  };
  const bool fl = p.runs<float>(), db = p.runs<double>();
  if (fl) add("BM_confidence<float>", BM_confidence<float>);
  if (db) add("BM_confidence<double>", BM_confidence<double>);
  if (fl) add("BM_carap<float, false>", BM_carap<float, false>);
  if (db) add("BM_carap<double, false>", BM_carap<double, false>);
  if (fl) add("BM_carap<float, true>", BM_carap<float, true>);
  if (db) add("BM_carap<double, true>", BM_carap<double, true>);
  if (fl) add("BM_lrm<float, 0>", BM_lrm<float, 0>);
  if (db) add("BM_lrm<double, 0>", BM_lrm<double, 0>);
  if (fl) add("BM_lrm<float, 1>", BM_lrm<float, 1>);
  if (db) add("BM_lrm<double, 1>", BM_lrm<double, 1>);
  if (fl) add("BM_lrm<float, 2>", BM_lrm<float, 2>);
  if (db) add("BM_lrm<double, 2>", BM_lrm<double, 2>);
  if (fl) add("BM_arap<float, false>", BM_arap<float, false>);
  if (fl) add("BM_arap<float, true>", BM_arap<float, true>);
  if (db) add("BM_arap<double, true>", BM_arap<double, true>);
  if (fl) add("BM_accel<float>", BM_accel<float>);
  if (db) add("BM_accel<double>", BM_accel<double>);
  smg::test::for_each_operator([&](auto op) {
    using Op = decltype(op);
    if (fl) add(std::string("list/") + Op::name + "<float>", BM_listed<Op, float>);
    if (db) add(std::string("list/") + Op::name + "<double>", BM_listed<Op, double>);
  });
  if (fl) add("BM_carap_plus_lrm<float>", BM_carap_plus_lrm<float>);
  if (db) add("BM_carap_plus_lrm<double>", BM_carap_plus_lrm<double>);
  if (fl) add("BM_regularizers<float, false>", BM_regularizers<float, false>);
  if (fl) add("BM_regularizers<float, true>", BM_regularizers<float, true>);
  if (db) add("BM_regularizers<double, true>", BM_regularizers<double, true>);
  if (locality) {
    if (fl) add("locality/carap_grad<float>/random", BM_locality<float, 0, false>);
    if (fl) add("locality/carap_grad<float>/morton", BM_locality<float, 0, true>);
    if (fl) add("locality/lrm_grad<float>/random", BM_locality<float, 1, false>);
    if (fl) add("locality/lrm_grad<float>/morton", BM_locality<float, 1, true>);
    if (db) add("locality/carap_grad<double>/random", BM_locality<double, 0, false>);
    if (db) add("locality/carap_grad<double>/morton", BM_locality<double, 0, true>);
    if (db) add("locality/lrm_grad<double>/random", BM_locality<double, 1, false>);
    if (db) add("locality/lrm_grad<double>/morton", BM_locality<double, 1, true>);
  }
  if (fl) add("BM_carap_residuals<float>", BM_carap_residuals<float>);
  if (db) add("BM_carap_residuals<double>", BM_carap_residuals<double>);
  if (fl) add("BM_lrm_residuals<float>", BM_lrm_residuals<float>);
  if (db) add("BM_lrm_residuals<double>", BM_lrm_residuals<double>);
  // Autodiff rows: double, one thread, one iteration per repetition (at least two repetitions,
  // so that the report, which keeps aggregates, lists them).
  if (db && cfg.ad_frames >= 2) {
    for (auto [name, f] : {std::pair{"BM_autodiff_carap", BM_autodiff_carap}, std::pair{"BM_autodiff_lrm", BM_autodiff_lrm}})
      smg_bench::protocol(benchmark::RegisterBenchmark(name, f)->Iterations(1)->Unit(benchmark::kMillisecond),
                          std::max(2, reps));
  }
  return smg_bench::run(argc, argv);
}
