// Energies at the size: N = 5000 nodes, T = 100 frames, K = 16 neighbours, gaps {1, 2, 4}
// (bench/notes/energy.md describes every row and counter).
//
// Counters beside each time:
//   ms                  wall time of one call (median of the repetitions)
//   err_vs_double       float rows: ‖g_float − g_double‖ / ‖g_double‖ over the gradients the
//                       row computes (energy-only rows: relative energy error); 0 for double
//   err_detach_vs_exact LRM with ω held constant: ‖g_detached − g_exact‖ / ‖g_exact‖ (double)
//   ad_ratio            autodiff rows: AutoDiffScalar time / analytic time on the same problem
//   ns_per_block        residual rows: time per residual block (with its Jacobians)
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <unsupported/Eigen/AutoDiff>

#include "energy/reference_energies.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/finite_diff.hpp"

namespace {

using smg::Index;
using smg::Vector3;
using smg::test::Scene;

constexpr Index kN = 5000, kT = 100, kK = 16;

// Several rigid bodies moving smoothly (rotation + translation), each node with a little
// non-rigid noise, some nodes corrupted: a scene where every factor and Huber's both zones
// are exercised. K nearest neighbours by frame-0 distance, weights 1/K.
Scene<double> make_scene(Index T, Index N) {
  smg::test::Rng rng(2024);
  Scene<double> s;
  s.resize(T, N);
  s.v.assign(s.v.size(), 1);
  s.c.assign(s.c.size(), 1.0);
  const int bodies = 12;
  std::vector<Vector3<double>> centre, spin, vel;
  for (int b = 0; b < bodies; ++b) {
    centre.push_back(rng.vec3(2.0));
    spin.push_back(rng.vec3(0.03));
    vel.push_back(rng.vec3(0.01));
  }
  for (Index i = 0; i < N; ++i) {
    const int b = static_cast<int>(i % bodies);
    const Vector3<double> p = centre[b] + rng.vec3(0.4);
    const smg::Quaternion<double> r0 = rng.quaternion();
    const bool corrupted = rng.uniform(0, 1) < 0.02;
    for (Index t = 0; t < T; ++t) {
      const smg::Quaternion<double> Q = smg::so3::exp(Vector3<double>(double(t) * spin[b]));
      Vector3<double> x = Q * (p - centre[b]) + centre[b] + double(t) * vel[b] + rng.vec3(0.002);
      if (corrupted) x += rng.vec3(0.03);
      s.set_pos(t, i, x);
      s.set_rot(t, i, Q * r0 * smg::so3::exp(rng.vec3(0.01)));
      s.v[static_cast<std::size_t>(t * N + i)] = rng.uniform(0, 1) < 0.95 ? 1 : 0;
    }
  }
  smg::test::knn_graph(s, kK);
  std::vector<double> c(s.v.size());
  smg::node_confidences<double>(s.positions(), s.visibility(), s.graph(), {},
                                {c.data(), s.T, s.N});
  s.c = c;
  return s;
}

const Scene<double>& scene() {
  static const Scene<double> s = make_scene(kT, kN);
  return s;
}
template <class S>
const Scene<S>& scene_as() {
  static const Scene<S> s = scene().cast<S>();
  return s;
}

smg::CarapOptions carap_options() { return {}; }  // gaps {1, 2, 4}, α 0.6, λc = λl = 1
smg::LrmOptions lrm_options(bool detach = false) {
  smg::LrmOptions o;
  o.detach_omega = detach;
  return o;
}

// Double-precision results, the references of the error columns.
struct Reference {
  double carap = 0, lrm = 0, lrm_detached = 0, arap = 0, conf_sum = 0;
  std::vector<double> carap_x, carap_r, lrm_x, lrm_detached_x, arap_x, arap_r, conf;
};
const Reference& reference() {
  static const Reference r = [] {
    Reference f;
    const Scene<double>& s = scene();
    const std::size_t n = s.x.size();
    f.carap_x.assign(n, 0.0);
    f.carap_r.assign(n, 0.0);
    f.lrm_x.assign(n, 0.0);
    f.lrm_detached_x.assign(n, 0.0);
    f.arap_x.assign(n, 0.0);
    f.arap_r.assign(n, 0.0);
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
    f.arap = smg::arap<double>(s.positions(), s.rotations(), s.graph(), {},
                               {f.arap_x.data(), s.T, s.N}, {f.arap_r.data(), s.T, s.N});
    return f;
  }();
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
void set_ms(benchmark::State& state) {
  state.counters["ms"] = benchmark::Counter(static_cast<double>(state.iterations()) * 1e-3,
                                            benchmark::Counter::kIsRate |
                                                benchmark::Counter::kInvert);
}
template <class S>
constexpr bool is_double() {
  return sizeof(S) == sizeof(double);
}

// The body every energy row shares: times `call()` (one evaluation, returning its energy), sets
// ms, and returns the energy of the last call.
template <class Call>
double time_energy(benchmark::State& state, Call&& call) {
  double e = 0;
  for (auto _ : state) {
    e = call();
    benchmark::DoNotOptimize(e);
  }
  set_ms(state);
  return e;
}
// err_vs_double: error() for float rows (evaluated only there), 0 for double.
template <class S, class Error>
void set_err_vs_double(benchmark::State& state, Error&& error) {
  state.counters["err_vs_double"] = is_double<S>() ? 0.0 : error();
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
  for (auto _ : state) {
    smg::node_confidences<S>(s.positions(), s.visibility(), s.graph(), {}, {c.data(), s.T, s.N},
                             {}, {}, &ws, threads(state));
    benchmark::DoNotOptimize(c.data());
  }
  set_ms(state);
  set_err_vs_double<S>(state, [&] { return relative_error(c, reference().conf); });
}

// ---- C-ARAP and plain ARAP (kGradient: energy and gradients w.r.t. positions and rotations) ----
// One row each; kCarap picks the energy, its double results are the references.
template <class S, bool kGradient, bool kCarap>
void rigidity_row(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size()), gr(s.x.size());
  smg::EnergyWorkspace<S> ws;
  const double e = time_energy(state, [&] {
    const smg::PositionsView<S> vx = grad_view(gx, s, kGradient);
    const smg::TangentsView<S> vr = tangent_view(gr, s, kGradient);
    if constexpr (kCarap)
      return double(smg::carap<S>(s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(), vx,
                                  vr, &ws, threads(state)));
    else
      return double(smg::arap<S>(s.positions(), s.rotations(), s.graph(), {}, vx, vr, &ws, threads(state)));
  });
  const Reference& r = reference();
  const double ref = kCarap ? r.carap : r.arap;
  const std::vector<double>& ref_x = kCarap ? r.carap_x : r.arap_x;
  const std::vector<double>& ref_r = kCarap ? r.carap_r : r.arap_r;
  set_err_vs_double<S>(state, [&] {
    return kGradient ? relative_error(gx, ref_x, gr, ref_r) : std::abs(e - ref) / ref;
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
template <class S, int kMode>
void BM_lrm(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size());
  smg::EnergyWorkspace<S> ws;
  const double e = time_energy(state, [&] {
    return double(smg::lrm<S>(s.positions(), s.confidence(), s.graph(), lrm_options(kMode == 2),
                              grad_view(gx, s, kMode > 0), &ws, threads(state)));
  });
  const Reference& r = reference();
  set_err_vs_double<S>(state, [&] {
    return kMode == 0 ? std::abs(e - r.lrm) / r.lrm : relative_error(gx, kMode == 1 ? r.lrm_x : r.lrm_detached_x);
  });
  if (kMode == 2) state.counters["err_detach_vs_exact"] = relative_error(r.lrm_detached_x, r.lrm_x);
}

// ---- The target: C-ARAP + LRM, energy + exact gradient, into one gradient buffer ----
template <class S>
void BM_carap_plus_lrm(benchmark::State& state) {
  const Scene<S>& s = scene_as<S>();
  std::vector<S> gx(s.x.size()), gr(s.x.size());
  smg::EnergyWorkspace<S> ws;
  time_energy(state, [&] {
    const smg::PositionsView<S> g = grad_view(gx, s, true);
    return double(smg::carap<S>(s.positions(), s.rotations(), s.confidence(), s.graph(), carap_options(), g,
                                tangent_view(gr, s, true), &ws, threads(state))) +
           double(smg::lrm<S>(s.positions(), s.confidence(), s.graph(), lrm_options(), g, &ws, threads(state)));
  });
  const Reference& r = reference();
  std::vector<double> sum(r.carap_x.size());
  for (std::size_t k = 0; k < sum.size(); ++k) sum[k] = r.carap_x[k] + r.lrm_x[k];
  set_err_vs_double<S>(state, [&] { return relative_error(gx, sum, gr, r.carap_r); });
  state.counters["target_ms"] = 100.0;
}

// ---- Residual + Jacobian forms, streamed through a visitor that forms 2 Jᵀ r per chunk-free
// sum (the sum of squares, so nothing is optimised away). Run on the first kResFrames frames:
// the per-block cost does not depend on T. ----
constexpr Index kResFrames = 10;
// The scene's first `frames` frames.
Scene<double> first_frames(Index frames) {
  Scene<double> r = scene();
  r.resize(frames, kN);
  return r;
}
template <class S>
const Scene<S>& residual_scene() {
  static const Scene<S> s = first_frames(kResFrames).cast<S>();
  return s;
}
// ns_per_block: wall time per residual block.
void set_ns_per_block(benchmark::State& state, double blocks) {
  state.counters["ns_per_block"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * blocks * 1e-9,
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
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
  blocks = smg::carap_residual_count(s.graph(), s.T, carap_options());
  set_ms(state);
  set_ns_per_block(state, static_cast<double>(blocks));
}
template <class S>
void BM_lrm_residuals(benchmark::State& state) {
  const Scene<S>& s = residual_scene<S>();
  const auto par = threads(state);
  constexpr std::size_t kPad = 16;  // no false sharing between threads
  std::vector<double> partial(static_cast<std::size_t>(smg::lrm_residual_chunks(s.T, s.N)) * kPad);
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
  set_ms(state);
  set_ns_per_block(state, static_cast<double>(s.T * s.N));
}

// ---- Eigen AutoDiffScalar, per term (the fair comparison): each C-ARAP pair term with an
// 18-entry fixed-size derivative vector (x_i, x_j at both frames, the two right tangents of
// R_i), each LRM neighbourhood with a derivative vector of 6·|N(i)| <= 96 entries (x_j and u_j
// of every neighbour, then u chained to x). Same equations, written straight from docs/design.md in
// tests/energy/reference_energies.hpp. Double, one thread, on the first kAdFrames frames; the
// analytic kernel is timed on the same sub-problem for ad_ratio. ----
constexpr Index kAdFrames = 8;
const Scene<double>& ad_scene() {
  static const Scene<double> s = first_frames(kAdFrames);
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
  for (auto _ : state) {
    autodiff();
    benchmark::DoNotOptimize(gx.data());
  }
  set_ms(state);
  smg::ParallelOptions one;
  one.threads = 1;
  smg::EnergyWorkspace<double> ws;
  const double analytic_seconds = seconds_of([&] { analytic(one, ws); }, 5);
  const double ad = seconds_of(autodiff, 1);
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

void Threads(benchmark::internal::Benchmark* b) {
  b->ArgName("threads")->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond)
      ->Repetitions(3)->ReportAggregatesOnly(true);
}

}  // namespace

BENCHMARK_TEMPLATE(BM_confidence, float)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_confidence, double)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap, float, false)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap, double, false)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap, float, true)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap, double, true)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm, float, 0)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm, double, 0)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm, float, 1)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm, double, 1)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm, float, 2)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm, double, 2)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_arap, float, false)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_arap, float, true)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_arap, double, true)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap_plus_lrm, float)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap_plus_lrm, double)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap_residuals, float)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_carap_residuals, double)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm_residuals, float)->Apply(Threads);
BENCHMARK_TEMPLATE(BM_lrm_residuals, double)->Apply(Threads);
// Two repetitions so that the report (which keeps median aggregates) lists them.
BENCHMARK(BM_autodiff_carap)->Iterations(1)->Repetitions(2)->ReportAggregatesOnly(true)
    ->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_autodiff_lrm)->Iterations(1)->Repetitions(2)->ReportAggregatesOnly(true)
    ->UseRealTime()->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
