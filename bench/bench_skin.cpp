// Skinning: distance-aware weights, DQB and LBS blending of many points — forward, forward
// with per-point Jacobians, and the batched backward (VJP) — float and double, 1 and 2
// threads; and the LBS-vs-DQB difference on a twisting pair. bench/notes/skin.md describes the
// scene and every counter.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include "bench_common.hpp"
#include "skin/skin_test_support.hpp"
#include "smg/skin.hpp"

namespace {

// Run-time sizes (main() reads them from the parameters before any scene is built).
smg::Index kT = 8, kN = 2000, kK = 16, kP = 32768, kPJac = 4096;
constexpr double kPi = 3.14159265358979323846;

// A smoothly deforming node cloud: nodes in a 4x4x1 slab; frame t bends and twists it
// (rotation angle proportional to x, up to ~90° at the far end), so neighbouring nodes move
// similarly but not rigidly — the regime DQB is used in. KNN graph (K = 16) on frame 0;
// sigma_n = mean distance to the node's neighbours; points scattered around random anchors.
struct Scene {
  std::vector<double> positions, quats, sigma, points, point_quats, weights;
  std::vector<std::int32_t> graph, drivers, t_ref, t_query;
  smg::Index D = kK + 1, edges = 0, edges_jac = 0;
};

const Scene& scene() {
  static const Scene s = [] {
    Scene r;
    std::mt19937_64 g(11);
    std::uniform_real_distribution<double> u(0, 1);
    std::normal_distribution<double> n(0, 1);
    std::vector<smg::Vector3<double>> x0(kN);
    for (auto& x : x0) x = smg::Vector3<double>(4 * u(g), 4 * u(g), u(g));
    for (smg::Index t = 0; t < kT; ++t)
      for (smg::Index i = 0; i < kN; ++i) {
        const double s = double(t) / (kT - 1);
        const smg::Quaternion<double> q =
            smg::so3::exp(smg::Vector3<double>(s * 0.4 * x0[i](0), s * 0.15 * x0[i](1), 0));
        const smg::Vector3<double> x = q * x0[i] + smg::Vector3<double>(0.3 * s, 0, 0.2 * s);
        r.positions.insert(r.positions.end(), {x(0), x(1), x(2)});
        r.quats.insert(r.quats.end(), {q.w(), q.x(), q.y(), q.z()});
      }
    r.graph.resize(kN * kK);
    r.sigma.resize(kN);
    std::vector<std::pair<double, std::int32_t>> d(kN);
    for (smg::Index i = 0; i < kN; ++i) {
      for (smg::Index j = 0; j < kN; ++j) d[j] = {(x0[i] - x0[j]).squaredNorm(), std::int32_t(j)};
      std::partial_sort(d.begin(), d.begin() + kK + 1, d.end());
      double mean = 0;
      for (smg::Index k = 0; k < kK; ++k) {
        r.graph[i * kK + k] = d[k + 1].second;  // d[0] is the node itself
        mean += std::sqrt(d[k + 1].first) / kK;
      }
      r.sigma[i] = mean;
    }
    std::vector<std::int32_t> anchor(kP);
    for (smg::Index p = 0; p < kP; ++p) {
      anchor[p] = std::int32_t(u(g) * kN) % kN;
      r.t_ref.push_back(std::int32_t(u(g) * kT) % kT);
      const double* a = &r.positions[(r.t_ref[p] * kN + anchor[p]) * 3];
      for (int c = 0; c < 3; ++c) r.points.push_back(a[c] + 0.1 * n(g));
      smg::Vector4<double> q(n(g), n(g), n(g), n(g));
      q.normalize();
      r.point_quats.insert(r.point_quats.end(), {q(0), q(1), q(2), q(3)});
    }
    r.t_query = {static_cast<std::int32_t>(kT - 1)};
    std::vector<double> gw(kN * kK, 1.0 / kK);
    r.drivers.resize(kP * r.D);
    smg::skin_drivers(smg::NeighborsView<double>(r.graph.data(), gw.data(), kN, kK),
                      {anchor.data(), kP}, {r.drivers.data(), kP, r.D});
    r.weights.resize(kP * r.D);
    smg::skinning_weights<double>({r.positions.data(), kT, kN}, {r.drivers.data(), kP, r.D},
                                  {r.t_ref.data(), kP}, {r.points.data(), kP},
                                  {r.sigma.data(), kN}, {r.weights.data(), kP, r.D});
    for (smg::Index p = 0; p < kP; ++p)
      for (smg::Index k = 0; k < r.D; ++k)
        if (r.drivers[p * r.D + k] >= 0) {
          ++r.edges;
          if (p < kPJac) ++r.edges_jac;
        }
    return r;
  }();
  return s;
}

template <class S>
std::vector<S> cast(const std::vector<double>& v) {
  return std::vector<S>(v.begin(), v.end());
}

// The scene's arrays in scalar S.
template <class S>
struct Views {
  std::vector<S> positions, quats, sigma, points, point_quats, weights;
  Views() {
    const Scene& s = scene();
    positions = cast<S>(s.positions);
    quats = cast<S>(s.quats);
    sigma = cast<S>(s.sigma);
    points = cast<S>(s.points);
    point_quats = cast<S>(s.point_quats);
    weights = cast<S>(s.weights);
  }
  smg::SkinNodes<S> nodes() const { return {{positions.data(), kT, kN}, {quats.data(), kT, kN}}; }
  smg::SkinPoints<S> pts(smg::Index P = kP) const {
    const Scene& s = scene();
    smg::SkinPoints<S> p;
    p.drivers = {s.drivers.data(), P, s.D};
    p.weights = {weights.data(), P, s.D};
    p.t_ref = {s.t_ref.data(), P};
    p.positions = {points.data(), P};
    p.quaternions = {point_quats.data(), P};
    return p;
  }
  smg::SkinIndexView query() const { return {scene().t_query.data(), 1}; }
};

template <class S>
const Views<S>& views() {
  static const Views<S> v;
  return v;
}

template <class S>
std::vector<S> blend_positions(smg::SkinMethod m, smg::Index P = kP) {
  const Views<S>& v = views<S>();
  std::vector<S> out(P * 3);
  smg::SkinBlendOutputs<S> o;
  o.positions = {out.data(), 1, P};
  smg::SkinOptions opt;
  opt.method = m;
  smg::skin_blend(v.nodes(), v.pts(P), v.query(), o, opt);
  return out;
}

template <class A, class B>
double max_abs_diff(const std::vector<A>& a, const std::vector<B>& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(double(a[i]) - double(b[i])));
  return m;
}

// Double against the independent reference of tests/skin (core dual quaternions, matrices).
double reference_error(smg::SkinMethod m) {
  const Scene& s = scene();
  const std::vector<double> out = blend_positions<double>(m);
  double err = 0;
  for (smg::Index p = 0; p < kP; p += 7) {
    smg::test::Drivers d;
    const smg::Index t = s.t_query[0], tr = s.t_ref[p];
    for (smg::Index k = 0; k < s.D && s.drivers[p * s.D + k] >= 0; ++k) {
      const smg::Index n = s.drivers[p * s.D + k];
      smg::SkinDriver<double> x;
      x.x_ref = Eigen::Map<const smg::Vector3<double>>(&s.positions[(tr * kN + n) * 3]);
      x.x_t = Eigen::Map<const smg::Vector3<double>>(&s.positions[(t * kN + n) * 3]);
      x.q_ref = smg::from_wxyz(&s.quats[(tr * kN + n) * 4]);
      x.q_t = smg::from_wxyz(&s.quats[(t * kN + n) * 4]);
      x.weight = s.weights[p * s.D + k];
      d.push_back(x);
    }
    const smg::Vector3<double> x = Eigen::Map<const smg::Vector3<double>>(&s.points[p * 3]);
    smg::Vector3<double> ref;
    if (m == smg::SkinMethod::dqb) {
      smg::Quaternion<double> q;
      smg::test::reference_dqb(d, x, smg::from_wxyz(&s.point_quats[p * 4]), &ref, &q);
    } else {
      ref = smg::test::reference_lbs(d, x);
    }
    err = std::max(err, (Eigen::Map<const smg::Vector3<double>>(&out[p * 3]) - ref).cwiseAbs().maxCoeff());
  }
  return err;
}

// ns_per_point: wall time per point; blend_rate: point x driver blends per second of wall time
// (both measured around the loop: Google Benchmark's kIsRate would divide by the process CPU
// time of all threads).
void rates(benchmark::State& state, const smg_bench::Stopwatch& clock, smg::Index points, smg::Index edges) {
  const double seconds = clock.seconds();
  state.counters["ns_per_point"] = smg_bench::per(state, seconds, double(points), 1e9);
  state.counters["blend_rate"] =
      benchmark::Counter(double(state.iterations()) * double(edges) / seconds);
}

// ---- skinning weights ----
template <class S>
void BM_weights(benchmark::State& state) {
  const Scene& s = scene();
  const Views<S>& v = views<S>();
  smg::ParallelOptions par;
  par.threads = int(state.range(0));
  std::vector<S> w(kP * s.D);
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    smg::skinning_weights<S>({v.positions.data(), kT, kN}, {s.drivers.data(), kP, s.D},
                             {s.t_ref.data(), kP}, {v.points.data(), kP}, {v.sigma.data(), kN},
                             {w.data(), kP, s.D}, par);
    benchmark::ClobberMemory();
  }
  rates(state, clock, kP, s.edges);
  state.counters["err_vs_ref"] = std::is_same_v<S, double> ? 0.0 : max_abs_diff(w, s.weights);
}

// ---- blend forward (values only) ----
template <class S, smg::SkinMethod M>
void BM_blend(benchmark::State& state) {
  const Scene& s = scene();
  const Views<S>& v = views<S>();
  std::vector<S> pos(kP * 3), quat(kP * 4);
  smg::SkinBlendOutputs<S> o;
  o.positions = {pos.data(), 1, kP};
  o.quaternions = {quat.data(), 1, kP};
  smg::SkinOptions opt;
  opt.method = M;
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    smg::skin_blend(v.nodes(), v.pts(), v.query(), o, opt, smg::ParallelOptions{int(state.range(0)), 0});
    benchmark::ClobberMemory();
  }
  rates(state, clock, kP, s.edges);
  state.counters["err_vs_ref"] = std::is_same_v<S, double>
                                     ? reference_error(M)
                                     : max_abs_diff(pos, blend_positions<double>(M));
  if (M == smg::SkinMethod::dqb && std::is_same_v<S, double> && state.range(0) == 1)
    state.counters["max_dqb_lbs_diff"] =
        max_abs_diff(blend_positions<double>(smg::SkinMethod::dqb),
                     blend_positions<double>(smg::SkinMethod::lbs));
}

// ---- blend forward with per-point Jacobians (6x13 per driver, 6x6 per point) ----
template <class S, smg::SkinMethod M>
void BM_blend_jacobians(benchmark::State& state) {
  const Scene& s = scene();
  const Views<S>& v = views<S>();
  std::vector<S> pos(kPJac * 3), Jd(kPJac * s.D * 78), Jp(kPJac * 36);
  smg::SkinBlendOutputs<S> o;
  o.positions = {pos.data(), 1, kPJac};
  o.J_drivers = {Jd.data(), 1, kPJac, s.D * 78};
  o.J_point = {Jp.data(), 1, kPJac, 36};
  smg::SkinOptions opt;
  opt.method = M;
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    smg::skin_blend(v.nodes(), v.pts(kPJac), v.query(), o, opt, smg::ParallelOptions{int(state.range(0)), 0});
    benchmark::ClobberMemory();
  }
  rates(state, clock, kPJac, s.edges_jac);
  if (!std::is_same_v<S, double>) {
    const Views<double>& vd = views<double>();
    std::vector<double> Jdd(Jd.size()), Jpd(Jp.size());
    smg::SkinBlendOutputs<double> od;
    od.J_drivers = {Jdd.data(), 1, kPJac, s.D * 78};
    od.J_point = {Jpd.data(), 1, kPJac, 36};
    smg::SkinOptions o2;
    o2.method = M;
    smg::skin_blend(vd.nodes(), vd.pts(kPJac), vd.query(), od, o2);
    // Largest entry error relative to the largest entry.
    double scale = 0;
    for (double x : Jdd) scale = std::max(scale, std::abs(x));
    state.counters["err_vs_ref"] = max_abs_diff(Jd, Jdd) / scale;
  } else {
    state.counters["err_vs_ref"] = 0;
  }
}

// ---- backward (VJP) into node positions/rotations and point gradients ----
template <class S>
struct BackwardRun {
  std::vector<S> gpos, grot, nx, nr, px, pr;
  smg::SkinWorkspace<S> ws;
  BackwardRun() {
    std::mt19937_64 g(5);
    std::normal_distribution<double> n(0, 1);
    for (smg::Index i = 0; i < kP * 3; ++i) gpos.push_back(S(n(g)));
    for (smg::Index i = 0; i < kP * 3; ++i) grot.push_back(S(n(g)));
    nx.assign(kT * kN * 3, S(0));
    nr = nx;
    px.assign(kP * 3, S(0));
    pr = px;
  }
  void run(smg::SkinMethod m, int threads) {
    const Views<S>& v = views<S>();
    smg::SkinBlendOutputGradients<S> go;
    go.positions = {gpos.data(), 1, kP};
    go.rotations = {grot.data(), 1, kP};
    smg::SkinBlendGradients<S> gr;
    gr.node_positions = {nx.data(), kT, kN};
    gr.node_rotations = {nr.data(), kT, kN};
    gr.points = {px.data(), kP};
    gr.point_rotations = {pr.data(), kP};
    smg::SkinOptions opt;
    opt.method = m;
    smg::skin_blend_backward(v.nodes(), v.pts(), v.query(), go, gr, ws, opt, smg::ParallelOptions{threads, 0});
  }
};

template <class S, smg::SkinMethod M>
void BM_backward(benchmark::State& state) {
  const Scene& s = scene();
  BackwardRun<S> b;
  b.run(M, int(state.range(0)));  // warm the workspace (incidence, edge buffer)
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    b.run(M, int(state.range(0)));
    benchmark::ClobberMemory();
  }
  rates(state, clock, kP, s.edges);
  if (!std::is_same_v<S, double>) {
    BackwardRun<S> f;
    BackwardRun<double> d;
    f.run(M, 1);
    d.run(M, 1);
    // ‖g_float − g_double‖ / ‖g_double‖ over all node gradients.
    double num = 0, den = 0;
    for (std::size_t i = 0; i < d.nx.size(); ++i) {
      num += std::pow(double(f.nx[i]) - d.nx[i], 2) + std::pow(double(f.nr[i]) - d.nr[i], 2);
      den += d.nx[i] * d.nx[i] + d.nr[i] * d.nr[i];
    }
    state.counters["err_vs_ref"] = std::sqrt(num / den);
  } else {
    state.counters["err_vs_ref"] = 0;
  }
}

// ---- the twisting pair: DQB vs LBS ----
// Two nodes at x = ±1; the +1 node twists by θ about the x axis. A tube of radius 0.3 around
// the axis (81 rings x 64 points, weights from skinning_weights with sigma 0.6) is blended.
// Counters: volume ratio after/before for each method (slices: every ring stays in its plane),
// and the largest |p'_DQB − p'_LBS| relative to the radius.
void BM_twist(benchmark::State& state) {
  const double theta = double(state.range(0)) * kPi / 180;
  const int rings = 81, sectors = 64;
  const double radius = 0.3;
  std::vector<double> pts;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sectors; ++j) {
      const double a = 2 * kPi * j / sectors;
      pts.insert(pts.end(), {-1 + 2.0 * i / (rings - 1), radius * std::cos(a), radius * std::sin(a)});
    }
  const smg::Index P = rings * sectors;
  const std::vector<double> positions = {-1, 0, 0, 1, 0, 0, -1, 0, 0, 1, 0, 0};
  const smg::Quaternion<double> r = smg::so3::exp(smg::Vector3<double>(theta, 0, 0));
  const std::vector<double> quats = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, r.w(), r.x(), r.y(), r.z()};
  const std::vector<std::int32_t> gi = {1, 0};
  const std::vector<double> gw = {1, 1}, sig = {0.6, 0.6};
  std::vector<std::int32_t> anchor(P), t_ref(P, 0), drivers(P * 2), tq = {1};
  for (smg::Index p = 0; p < P; ++p) anchor[p] = pts[p * 3] < 0 ? 0 : 1;
  smg::skin_drivers(smg::NeighborsView<double>(gi.data(), gw.data(), 2, 1), {anchor.data(), P},
                    {drivers.data(), P, 2});
  std::vector<double> w(P * 2);
  smg::skinning_weights<double>({positions.data(), 2, 2}, {drivers.data(), P, 2}, {t_ref.data(), P},
                                {pts.data(), P}, {sig.data(), 2}, {w.data(), P, 2});
  smg::SkinPoints<double> sp;
  sp.drivers = {drivers.data(), P, 2};
  sp.weights = {w.data(), P, 2};
  sp.t_ref = {t_ref.data(), P};
  sp.positions = {pts.data(), P};
  const smg::SkinNodes<double> nodes{{positions.data(), 2, 2}, {quats.data(), 2, 2}};
  auto run = [&](smg::SkinMethod m) {
    std::vector<double> out(P * 3);
    smg::SkinBlendOutputs<double> o;
    o.positions = {out.data(), 1, P};
    smg::SkinOptions opt;
    opt.method = m;
    smg::skin_blend(nodes, sp, {tq.data(), 1}, o, opt, smg::ParallelOptions{1, 0});
    return out;
  };
  auto volume = [&](const std::vector<double>& x) {
    double v = 0, prev = 0;
    for (int i = 0; i < rings; ++i) {
      double area = 0;
      for (int j = 0; j < sectors; ++j) {
        const double* a = &x[(i * sectors + j) * 3];
        const double* b = &x[(i * sectors + (j + 1) % sectors) * 3];
        area += 0.5 * (a[1] * b[2] - a[2] * b[1]);
      }
      if (i > 0) v += 0.5 * (area + prev) * (2.0 / (rings - 1));
      prev = area;
    }
    return v;
  };
  const smg::SkinMethod m = state.range(1) ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
  const smg_bench::Stopwatch clock;
  for (auto _ : state) benchmark::DoNotOptimize(run(m));
  rates(state, clock, P, 2 * P);
  const std::vector<double> dqb = run(smg::SkinMethod::dqb), lbs = run(smg::SkinMethod::lbs);
  const double v0 = volume(pts);
  state.counters["vol_ratio_dqb"] = volume(dqb) / v0;
  state.counters["vol_ratio_lbs"] = volume(lbs) / v0;
  state.counters["max_dqb_lbs_diff"] = max_abs_diff(dqb, lbs) / radius;
}

using smg::SkinMethod;

}  // namespace

int main(int argc, char** argv) {
  smg_bench::Params p(argc, argv, "skin");
  kN = p.integer("n", 2000, "nodes N");
  kT = p.integer("t", 8, "frames T");
  kK = p.integer("k", 16, "neighbours K (drivers per point: K + 1)");
  kP = p.integer("points", 32768, "points P of the weight, blend and backward rows");
  kPJac = p.integer("points_jac", 4096, "points of the Jacobian rows");
  const std::vector<long> threads = p.list("threads", {1, 2}, "thread counts");
  p.precision();
  const int reps = p.reps(1);
  p.finish();
  if (kN <= kK || kT < 2 || kP < 1 || kPJac < 1 || kPJac > kP) {
    std::fprintf(stderr, "bench_skin: need n > k, t >= 2, 1 <= points_jac <= points\n");
    return 2;
  }
  // all_threads = false: only the first thread count (rows that were single-threaded before).
  auto add = [&](const char* name, void (*f)(benchmark::State&), bool is_double, bool all_threads = true) {
    if (!(is_double ? p.runs<double>() : p.runs<float>())) return;
    auto* b = benchmark::RegisterBenchmark(name, f)->Unit(benchmark::kMillisecond);
    for (long t : threads) {
      b->Arg(t);
      if (!all_threads) break;
    }
    smg_bench::protocol(b, reps);
  };
  using smg::SkinMethod;
  add("BM_weights<double>", BM_weights<double>, true);
  add("BM_weights<float>", BM_weights<float>, false);
  add("BM_blend<double, SkinMethod::dqb>", BM_blend<double, SkinMethod::dqb>, true);
  add("BM_blend<float, SkinMethod::dqb>", BM_blend<float, SkinMethod::dqb>, false);
  add("BM_blend<double, SkinMethod::lbs>", BM_blend<double, SkinMethod::lbs>, true);
  add("BM_blend<float, SkinMethod::lbs>", BM_blend<float, SkinMethod::lbs>, false);
  add("BM_blend_jacobians<double, SkinMethod::dqb>", BM_blend_jacobians<double, SkinMethod::dqb>, true);
  add("BM_blend_jacobians<float, SkinMethod::dqb>", BM_blend_jacobians<float, SkinMethod::dqb>, false, false);
  add("BM_blend_jacobians<double, SkinMethod::lbs>", BM_blend_jacobians<double, SkinMethod::lbs>, true, false);
  add("BM_backward<double, SkinMethod::dqb>", BM_backward<double, SkinMethod::dqb>, true);
  add("BM_backward<float, SkinMethod::dqb>", BM_backward<float, SkinMethod::dqb>, false);
  add("BM_backward<double, SkinMethod::lbs>", BM_backward<double, SkinMethod::lbs>, true, false);
  if (p.runs<double>())
    smg_bench::protocol(benchmark::RegisterBenchmark("BM_twist", BM_twist)->Args({90, 0})->Args({90, 1})->Args({150, 0})
                            ->Args({150, 1})->Unit(benchmark::kMicrosecond),
                        reps);
  return smg_bench::run(argc, argv);
}
