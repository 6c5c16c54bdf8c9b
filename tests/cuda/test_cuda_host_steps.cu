// The per-element steps of the CUDA LRM and DQB kernels (smg/cuda/lrm.cuh, dqb.cuh) and of the
// in-edge builder behind build_reverse_graph and build_driver_incidence (smg/cuda/common.cuh),
// run by host loops: the builder's steps (its atomics emulated one step at a time, in any order)
// give the host construction's offsets and entries; the scheme (gathers in the CPU's order,
// velocity pass, driver incidence, query frames read per query) reproduces the CPU smg::lrm /
// smg::skin_blend / smg::skin_blend_backward bit for bit on the host (where no FMA contraction
// differs), for float and double, int32 and int64 indices. Needs no GPU: the suite "cuda-host"
// can run on machines without one (doctest -ts=cuda-host).
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "smg/cuda/dqb.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/energy/lrm.hpp"
#include "smg/skin/blend.hpp"

#include "cuda/cuda_test_support.cuh"

namespace {

using smg::Index;

double uniform(std::mt19937_64& rng, double a = -1, double b = 1) {
  return std::uniform_real_distribution<double>(a, b)(rng);
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// max |a − b| / max |b| over two arrays (the error relative to the array's scale).
template <class T>
double max_rel_diff(const std::vector<T>& a, const std::vector<T>& b) {
  double scale = 0, err = 0;
  for (std::size_t k = 0; k < a.size() && k < b.size(); ++k) {
    scale = std::max(scale, std::abs(double(b[k])));
    err = std::max(err, std::abs(double(a[k]) - double(b[k])));
  }
  return a.size() == b.size() ? err / std::max(scale, 1e-300) : 1e300;
}

// The device builder (detail::build_in_edges) run by its per-element steps in host loops: the
// count and fill steps over the slots in `order` (a permutation of [0, rows·width): the order in
// which the device's atomics happen to land), the one-block scan as its kThreads threads (chunk
// sums, the exclusive scan thread 0 does, chunk offsets), then the per-target sort. Arrays start
// filled with garbage, as device scratch does; `ent` is cut to the offsets[nodes] entries used.
template <class I>
void in_edges_by_steps(const std::vector<I>& table, Index nodes, const std::vector<Index>& order,
                       std::vector<std::int32_t>& off, std::vector<std::int64_t>& ent) {
  namespace d = smg::cuda::detail;
  constexpr int threads = smg::cuda::kThreads;
  const Index slots = Index(table.size());
  std::vector<std::int32_t> counts(static_cast<std::size_t>(nodes + 1), 0);  // the memset
  for (const Index e : order) d::in_edges_count_at(e, table.data(), nodes, counts.data());
  off.assign(static_cast<std::size_t>(nodes + 1), -7);
  std::vector<std::int32_t> part(threads);
  for (int t = 0; t < threads; ++t) part[static_cast<std::size_t>(t)] = d::in_edges_chunk_sum(t, threads, counts.data(), nodes);
  std::int32_t run = 0;
  for (int t = 0; t < threads; ++t) {
    d::in_edges_chunk_offsets(t, threads, counts.data(), nodes, run, off.data());
    run += part[static_cast<std::size_t>(t)];
  }
  off[static_cast<std::size_t>(nodes)] = run;
  std::vector<std::int32_t> cursor = off;  // the device-to-device copy
  ent.assign(static_cast<std::size_t>(slots > 0 ? slots : 1), -7);
  for (const Index e : order) d::in_edges_fill_at(e, table.data(), nodes, cursor.data(), ent.data());
  for (Index j = 0; j < nodes; ++j) d::in_edges_sort_at(j, off.data(), ent.data());
  ent.resize(static_cast<std::size_t>(run));
}

// The in-edge lists as the device builds them (slots in increasing order).
template <class I>
void in_edges(const std::vector<I>& table, Index nodes, std::vector<std::int32_t>& off,
              std::vector<std::int64_t>& ent) {
  std::vector<Index> order(table.size());
  std::iota(order.begin(), order.end(), Index(0));
  in_edges_by_steps(table, nodes, order, off, ent);
}

// A table [rows][width] over `nodes` targets: random targets with some −1 padding and, with
// `out_of_range`, entries < −1 and >= nodes (not edges: skipped); with `heavy`, a third of the
// entries on target 0 (a long list for the sort).
template <class I>
std::vector<I> random_table(Index rows, Index width, Index nodes, bool out_of_range, bool heavy,
                            std::mt19937_64& rng) {
  std::vector<I> t(static_cast<std::size_t>(rows * width));
  for (auto& v : t) {
    const double u = uniform(rng, 0, 1);
    if (u < 0.15)
      v = I(-1);
    else if (out_of_range && u < 0.2)
      v = I(nodes + Index(uniform(rng, 0, 3)));
    else if (out_of_range && u < 0.25)
      v = I(-2 - Index(uniform(rng, 0, 3)));
    else if (heavy && u < 0.5)
      v = I(0);
    else
      v = I(Index(uniform(rng, 0, 1) * double(nodes)) % (nodes > 0 ? nodes : 1));
  }
  if (out_of_range && !t.empty()) t.back() = std::numeric_limits<I>::max();  // far out of range
  return t;
}

template <class I>
void in_edges_case(Index rows, Index width, Index nodes, bool out_of_range, bool heavy,
                   std::uint64_t seed) {
  CAPTURE(rows);
  CAPTURE(width);
  CAPTURE(nodes);
  CAPTURE(sizeof(I));
  CAPTURE(seed);
  std::mt19937_64 rng(seed);
  const std::vector<I> table = random_table<I>(rows, width, nodes, out_of_range, heavy, rng);
  std::vector<std::int32_t> off_ref, off;
  std::vector<std::int64_t> ent_ref, ent;
  smg::test::cuda::host_in_edges(table, nodes, off_ref, ent_ref);
  in_edges(table, nodes, off, ent);
  CHECK(off == off_ref);
  CHECK(ent == ent_ref);
  // The atomics land in any order: the result after the per-target sort is the same.
  std::vector<Index> order(table.size());
  std::iota(order.begin(), order.end(), Index(0));
  for (int r = 0; r < 3; ++r) {
    if (r == 0)
      std::reverse(order.begin(), order.end());
    else
      std::shuffle(order.begin(), order.end(), rng);
    in_edges_by_steps(table, nodes, order, off, ent);
    CHECK(off == off_ref);
    CHECK(ent == ent_ref);
  }
  // Sanity of the reference itself: every valid slot once, none of the others.
  std::int64_t valid = 0;
  for (const I j : table) valid += j >= 0 && Index(j) < nodes;
  CHECK(std::int64_t(off_ref.back()) == valid);
  bool grouped = true;
  for (Index j = 0; j < nodes; ++j)
    for (std::int32_t i = off_ref[static_cast<std::size_t>(j)]; i < off_ref[static_cast<std::size_t>(j + 1)]; ++i) {
      const std::int64_t e = ent_ref[static_cast<std::size_t>(i)];
      grouped = grouped && Index(table[static_cast<std::size_t>(e)]) == j &&
                (i == off_ref[static_cast<std::size_t>(j)] || ent_ref[static_cast<std::size_t>(i - 1)] < e);
    }
  CHECK(grouped);
}

template <class S, class I>
void lrm_steps_case(Index T, Index N, Index K, bool conf, const smg::LrmOptions& o, std::uint64_t seed) {
  CAPTURE(seed);
  CAPTURE(sizeof(S));
  CAPTURE(sizeof(I));
  std::mt19937_64 rng(seed);
  std::vector<S> x(static_cast<std::size_t>(T * N * 3)), c(conf ? static_cast<std::size_t>(T * N) : 0),
      w(static_cast<std::size_t>(N * K), S(0)), g0(static_cast<std::size_t>(T * N * 3));
  std::vector<I> idx(static_cast<std::size_t>(N * K), -1);
  for (auto& v : x) v = S(uniform(rng));
  for (auto& v : c) v = S(uniform(rng, 0, 1));
  for (auto& v : g0) v = S(uniform(rng));
  for (Index i = 0; i < N; ++i) {
    const Index deg = std::min<Index>({K, N - 1, 4 + Index(uniform(rng, 0, 1) * double(K))});
    std::vector<Index> p;
    for (Index j = 0; j < N; ++j)
      if (j != i) p.push_back(j);
    std::shuffle(p.begin(), p.end(), rng);
    for (Index k = 0; k < deg; ++k) {
      idx[static_cast<std::size_t>(i * K + k)] = I(p[static_cast<std::size_t>(k)]);
      w[static_cast<std::size_t>(i * K + k)] = S(uniform(rng, 0.2, 1));
    }
  }
  const smg::NeighborsView<S, I> g(idx.data(), w.data(), N, K);
  smg::FrameScalarsView<const S> cv;
  if (conf) cv = smg::FrameScalarsView<const S>(c.data(), T, N);
  const smg::PositionsView<const S> xv(x.data(), T, N);
  std::vector<S> g_cpu = g0, om_cpu(x.size(), S(0));
  const double e_cpu = double(smg::lrm<S, I>(xv, cv, g, o, smg::PositionsView<S>(g_cpu.data(), T, N),
                                             nullptr, {}, smg::TangentsView<S>(om_cpu.data(), T, N)));

  std::vector<std::int32_t> off;
  std::vector<std::int64_t> ent;
  in_edges(idx, N, off, ent);
  double scale = o.weight;
  if (o.normalization == smg::Normalization::mean) scale /= double(T * Index(ent.size()));
  smg::cuda::detail::LrmKernelArgs<S> a;
  a.p.huber_delta = smg::Literal<S>(o.huber_delta);
  a.p.mu_factor = smg::lrm_mu_factor<S>();
  a.p.detach_omega = o.detach_omega;
  a.p.gradient = true;
  a.alpha = smg::Literal<S>(o.alpha);
  a.scale = smg::Literal<S>(scale);
  const Index n = T * N;
  std::vector<smg::Accumulator<S>> terms(static_cast<std::size_t>(n));
  std::vector<S> edges(static_cast<std::size_t>(6 * n * K)), nodes(static_cast<std::size_t>(6 * n));
  std::vector<S> g_gpu = g0, om_gpu(x.size(), S(0));
  S* gxe = edges.data();
  S* gue = gxe + 3 * n * K;
  for (Index e = 0; e < n; ++e)
    smg::cuda::detail::lrm_term_at<S, I, 32>(e, xv, cv, g, a, terms.data(), gxe, gue,
                                             smg::TangentsView<S>(om_gpu.data(), T, N));
  for (Index e = 0; e < n; ++e)
    smg::cuda::detail::lrm_gather_at<S>(e, N, K, off.data(), ent.data(), gxe, gue, nodes.data(),
                                        nodes.data() + 3 * n);
  for (Index e = 0; e < n; ++e)
    smg::cuda::detail::lrm_velocity_at<S>(e, T, N, nodes.data(), nodes.data() + 3 * n,
                                          smg::PositionsView<S>(g_gpu.data(), T, N));
  double e_gpu = 0;
  for (const auto v : terms) e_gpu += double(v);
  e_gpu *= scale;
  CHECK(e_gpu == doctest::Approx(e_cpu).epsilon(1e-12));
  // ω is one element function's output per (frame, node): bitwise. The gradient sums the same
  // contributions in another order (the CPU's driver adds them per neighbour into its block's
  // rows, the CUDA steps gather per edge), so it agrees to rounding: 1e-12 relative in double.
  CHECK(max_rel_diff(g_gpu, g_cpu) <= (sizeof(S) == 8 ? 1e-12 : 2e-6));
  CHECK(same_bits(om_gpu, om_cpu));
}

// With `bad_queries`, t_query also holds frames outside [0, T) (−1, T, 2^30 − 1): the steps
// give NaN forward outputs for those queries and skip them in the backward, so everything else
// equals the CPU run on t_query without them.
template <class S>
void dqb_steps_case(Index T, Index N, Index P, Index D, Index Q, smg::SkinMethod m, std::uint64_t seed,
                    bool bad_queries = false) {
  CAPTURE(seed);
  CAPTURE(sizeof(S));
  CAPTURE(smg::to_string(m));
  CAPTURE(bad_queries);
  std::mt19937_64 rng(seed);
  std::vector<S> xn(static_cast<std::size_t>(T * N * 3)), qn(static_cast<std::size_t>(T * N * 4)),
      w(static_cast<std::size_t>(P * D), S(0)), pts(static_cast<std::size_t>(P * 3)),
      pq(static_cast<std::size_t>(P * 4));
  std::vector<std::int32_t> drv(static_cast<std::size_t>(P * D), -1), tref(static_cast<std::size_t>(P)),
      tq(static_cast<std::size_t>(Q));
  for (auto& v : xn) v = S(uniform(rng, -2, 2));
  for (auto& v : qn) v = S(uniform(rng));
  for (auto& v : pts) v = S(uniform(rng, -2, 2));
  for (auto& v : pq) v = S(uniform(rng));
  for (Index p = 0; p < P; ++p) {
    const Index deg = std::min<Index>({D, N, 1 + Index(uniform(rng, 0, 1) * double(D))});
    std::vector<std::int32_t> perm(static_cast<std::size_t>(N));
    for (Index k = 0; k < N; ++k) perm[static_cast<std::size_t>(k)] = std::int32_t(k);
    std::shuffle(perm.begin(), perm.end(), rng);
    for (Index k = 0; k < deg; ++k) {
      drv[static_cast<std::size_t>(p * D + k)] = perm[static_cast<std::size_t>(k)];
      w[static_cast<std::size_t>(p * D + k)] = S(uniform(rng, 0.05, 1));
    }
    tref[static_cast<std::size_t>(p)] = std::int32_t(Index(uniform(rng, 0, 1) * double(T)) % T);
  }
  for (auto& v : tq) v = std::int32_t(Index(uniform(rng, 0, 1) * double(T)) % T);
  if (bad_queries) {  // between the valid ones, and first
    const std::int32_t bad[] = {-1, std::int32_t(T), (std::int32_t(1) << 30) - 1};
    for (std::size_t i = 0; i < 3; ++i)
      tq.insert(tq.begin() + std::ptrdiff_t(i == 0 ? 0 : std::min(tq.size(), 2 * i + 1)), bad[i]);
    Q = Index(tq.size());
  }
  std::vector<Index> good;  // the queries with a frame in range
  std::vector<std::int32_t> tq_good;
  for (Index q = 0; q < Q; ++q)
    if (tq[static_cast<std::size_t>(q)] >= 0 && tq[static_cast<std::size_t>(q)] < T) {
      good.push_back(q);
      tq_good.push_back(tq[static_cast<std::size_t>(q)]);
    }
  const Index Qg = Index(good.size());
  REQUIRE((Qg < Q) == bad_queries);
  smg::SkinNodes<S> nodes;
  nodes.positions = smg::PositionsView<const S>(xn.data(), T, N);
  nodes.quaternions = smg::QuaternionsView<const S>(qn.data(), T, N);
  smg::SkinPoints<S> pv;
  pv.drivers = smg::SkinDriversView(drv.data(), P, D);
  pv.weights = smg::TableView<const S, Eigen::Dynamic>(w.data(), P, D);
  pv.t_ref = smg::SkinIndexView(tref.data(), P);
  pv.positions = smg::TableView<const S, 3>(pts.data(), P);
  pv.quaternions = smg::TableView<const S, 4>(pq.data(), P);
  const smg::SkinIndexView tv(tq.data(), Q);
  const smg::SkinIndexView tv_good(tq_good.data(), Qg);
  smg::SkinOptions opt;
  opt.method = m;

  // The rows [Q][P][dim] of the queries in `good` ([Qg][P][dim]).
  auto good_rows = [&](const std::vector<S>& a) {
    const std::size_t row = a.size() / static_cast<std::size_t>(Q);
    std::vector<S> r;
    for (const Index q : good)
      r.insert(r.end(), a.begin() + std::ptrdiff_t(std::size_t(q) * row),
               a.begin() + std::ptrdiff_t(std::size_t(q + 1) * row));
    return r;
  };
  // Eleven arrays: forward outputs, then the gradient buffers (random start: both add to them).
  // The CPU runs on the good queries only (Qg of them), the steps on all Q.
  auto run = [&](bool steps, std::vector<std::vector<S>>& A) {
    const Index Qr = steps ? Q : Qg;
    std::mt19937_64 r2(9);
    auto fill = [&](Index len) {
      std::vector<S> v(static_cast<std::size_t>(len));
      for (auto& x : v) x = S(uniform(r2));
      return v;
    };
    A = {std::vector<S>(static_cast<std::size_t>(Qr * P * 3), S(0)),
         std::vector<S>(static_cast<std::size_t>(Qr * P * 4), S(0)),
         std::vector<S>(static_cast<std::size_t>(Qr * P * D * 78), S(-7)),
         std::vector<S>(static_cast<std::size_t>(Qr * P * 36), S(0)),
         fill(T * N * 3), fill(T * N * 3), fill(T * N * 4), fill(P * 3), fill(P * 3), fill(P * 4),
         fill(P * D)};
    std::vector<S> gop = fill(Q * P * 3), gor = fill(Q * P * 3), goq = fill(Q * P * 4);
    if (!steps) {
      gop = good_rows(gop);
      gor = good_rows(gor);
      goq = good_rows(goq);
    }
    smg::SkinBlendOutputs<S> o;
    o.positions = smg::SequenceView<S, 3>(A[0].data(), Qr, P);
    o.quaternions = smg::SequenceView<S, 4>(A[1].data(), Qr, P);
    o.J_drivers = smg::SequenceView<S, Eigen::Dynamic>(A[2].data(), Qr, P, D * 78);
    o.J_point = smg::SequenceView<S, Eigen::Dynamic>(A[3].data(), Qr, P, 36);
    smg::SkinBlendGradients<S> g;
    g.node_positions = smg::PositionsView<S>(A[4].data(), T, N);
    g.node_rotations = smg::TangentsView<S>(A[5].data(), T, N);
    g.node_quaternions = smg::QuaternionsView<S>(A[6].data(), T, N);
    g.points = smg::TableView<S, 3>(A[7].data(), P);
    g.point_rotations = smg::TableView<S, 3>(A[8].data(), P);
    g.point_quaternions = smg::TableView<S, 4>(A[9].data(), P);
    g.weights = smg::TableView<S, Eigen::Dynamic>(A[10].data(), P, D);
    smg::SkinBlendOutputGradients<S> go;
    go.positions = smg::SequenceView<const S, 3>(gop.data(), Qr, P);
    go.rotations = smg::SequenceView<const S, 3>(gor.data(), Qr, P);
    go.quaternions = smg::SequenceView<const S, 4>(goq.data(), Qr, P);
    if (!steps) {
      smg::skin_blend<S>(nodes, pv, tv_good, o, opt);
      smg::SkinWorkspace<S> ws;
      smg::skin_blend_backward<S>(nodes, pv, tv_good, go, g, ws, opt);
      return;
    }
    for (Index e = 0; e < Q * P; ++e) smg::cuda::detail::skin_forward_at<S, 32>(e, nodes, pv, tv, o, m);
    std::vector<std::int32_t> off;
    std::vector<std::int64_t> ent;
    in_edges(drv, N, off, ent);
    std::vector<S> buf(static_cast<std::size_t>(P * D * smg::cuda::detail::kSkinEdgeStride));
    for (Index q = 0; q < Q; ++q) {
      for (Index p = 0; p < P; ++p)
        smg::cuda::detail::skin_backward_point_at<S, 32>(p, nodes, pv, tv, q, go, g, m, buf.data());
      for (Index nn = 0; nn < N; ++nn)
        smg::cuda::detail::skin_backward_node_at<S>(nn, nodes, pv, tv, q, g, off.data(), ent.data(), buf.data());
    }
  };
  std::vector<std::vector<S>> cpu, steps;
  run(false, cpu);
  run(true, steps);
  const char* names[] = {"positions", "quaternions", "J_drivers", "J_point", "grad_node_positions",
                         "grad_node_rotations", "grad_node_quaternions", "grad_points",
                         "grad_point_rotations", "grad_point_quaternions", "grad_weights"};
  for (std::size_t i = 0; i < cpu.size(); ++i) {
    CAPTURE(names[i]);
    if (i < 4 && bad_queries) {
      // The forward outputs: the good queries' rows equal the CPU's; the others are all NaN.
      CHECK(same_bits(good_rows(steps[i]), cpu[i]));
      const std::size_t row = steps[i].size() / static_cast<std::size_t>(Q);
      bool nan = true;
      for (Index q = 0; q < Q; ++q)
        if (std::find(good.begin(), good.end(), q) == good.end())
          for (std::size_t k = std::size_t(q) * row; k < std::size_t(q + 1) * row; ++k)
            nan = nan && steps[i][k] != steps[i][k];
      CHECK(nan);
      continue;
    }
    CHECK(same_bits(steps[i], cpu[i]));
  }
}

}  // namespace

TEST_SUITE("cuda-host") {
  TEST_CASE("cuda lrm steps on the host reproduce the CPU lrm (ω bit for bit, gradient to 1e-12)") {
    smg::LrmOptions o;
    o.huber_delta = 0.3;
    lrm_steps_case<double, std::int32_t>(5, 40, 8, true, o, 1);
    lrm_steps_case<float, std::int64_t>(5, 40, 16, true, o, 2);
    lrm_steps_case<double, std::int32_t>(2, 30, 6, true, o, 3);
    o.normalization = smg::Normalization::mean;
    o.detach_omega = true;
    o.weight = 0.7;
    lrm_steps_case<double, std::int64_t>(7, 40, 32, false, o, 4);
    lrm_steps_case<float, std::int32_t>(1, 30, 6, true, o, 5);
  }

  TEST_CASE("cuda dqb steps on the host reproduce the CPU skin_blend and its backward bit for bit") {
    for (const smg::SkinMethod m : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
      dqb_steps_case<double>(4, 20, 100, 6, 3, m, 11);
      dqb_steps_case<float>(3, 30, 80, 17, 2, m, 12);
    }
  }

  TEST_CASE("cuda dqb steps: query frames out of range give NaN outputs and are skipped in the backward") {
    for (const smg::SkinMethod m : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
      dqb_steps_case<double>(4, 20, 60, 6, 3, m, 13, true);
      dqb_steps_case<float>(3, 25, 50, 9, 2, m, 14, true);
    }
  }

  TEST_CASE("cuda in-edge builder steps (build_reverse_graph, build_driver_incidence) equal the host construction") {
    // graphs: rows == nodes
    in_edges_case<std::int32_t>(40, 8, 40, false, false, 21);
    in_edges_case<std::int64_t>(40, 16, 40, true, false, 22);
    // driver tables: rows != nodes, more and fewer rows than targets
    in_edges_case<std::int32_t>(300, 17, 25, true, false, 23);
    in_edges_case<std::int64_t>(300, 9, 25, false, true, 24);
    in_edges_case<std::int32_t>(7, 32, 600, true, false, 25);  // more targets than scan threads
    in_edges_case<std::int64_t>(2000, 3, 1000, true, true, 26);
    // edge cases: one target, no targets (everything skipped), an empty table
    in_edges_case<std::int32_t>(50, 4, 1, true, false, 27);
    in_edges_case<std::int64_t>(20, 5, 0, true, false, 28);
    in_edges_case<std::int32_t>(0, 6, 10, false, false, 29);
  }
}
