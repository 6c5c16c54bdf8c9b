// Semantic motion graph: build time, memory and error against N and T (bench/notes/graph.md).
//
// Scenes: tests/graph/synthetic_scene.hpp (rigid objects on random paths through a shared
// volume, visibility windows with dropouts). Every benchmark reports, beside its time:
//   knn/<S>/N/T            exact trajectory KNN (k = 16, paper aggregation, automatic segments)
//     mismatched_rows      rows that differ (ids or distances, bitwise) from the all-pairs
//                          reference trajectory_knn_brute_force in the same precision; every row
//                          when N*N*T <= 2.5e9, else 64 sampled rows (checked_rows says which)
//     rows_differ_vs_f64   float only: fraction of checked rows whose neighbour ids differ from
//                          the double reference on the same (float-rounded) inputs
//     dist_rel_err_vs_f64  float only: max relative error of the neighbour distances against it
//     pairs_per_node       exact pair distances evaluated per node (brute force: N - 1)
//     scratch_mb           memory the builder allocated (tracked: store, trees, state, scratch)
//     peak_rss_mb          peak resident memory of a fresh process that generates the scene
//                          and builds once (getrusage ru_maxrss); input_mb of it are the
//                          positions + visibility arrays themselves
//   knn_brute_force/...    the all-pairs reference, timed (small N only)
//   knn_segments/...       the exact KNN with a fixed segment length L against automatic (0)
//   descriptors/...        semantic_descriptors; angle_err_vs_f64 for float
//   graph/...              descriptors + KNN + gate + weights, with graph statistics
//   node_selection/...     greedy cover: node count and coverage error against the unit
// Beside each wall time: process CPU time over all threads and the load (bench_common.hpp).
// Parameters (flags or SMG_BENCH_*, --smg_help): --n=1000,5000,20000,50000 --t=100,400 --k=16
// --threads=0 (0: all hardware threads) --precision=both --reps=1 --descriptor_n=20000
// --segments_n=10000. With --benchmark_min_time below 0.05 (scripts/bench.sh --smoke) only the
// smallest sizes run (unless sizes are given).
#include <benchmark/benchmark.h>

#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "graph/synthetic_scene.hpp"
#include "smg/graph.hpp"

namespace {

using smg::Index;

struct Key {
  Index N = 0, T = 0, C = 0;
  double speed = 1.0;
  bool operator==(const Key& o) const { return N == o.N && T == o.T && C == o.C && speed == o.speed; }
};

// One scene in double, kept while consecutive benchmarks use it.
const smg::test::GraphScene<double>& scene(const Key& key) {
  static Key cached;
  static std::unique_ptr<smg::test::GraphScene<double>> sc;
  if (!sc || !(cached == key)) {
    sc.reset();
    smg::test::SceneOptions o;
    o.nodes = key.N;
    o.frames = key.T;
    o.channels = key.C;
    o.speed = key.speed;
    o.objects = 8;
    o.seed = 2024;
    sc = std::make_unique<smg::test::GraphScene<double>>(smg::test::make_scene<double>(o));
    cached = key;
  }
  return *sc;
}

template <class S>
std::vector<S> cast(const std::vector<double>& v) {
  return std::vector<S>(v.begin(), v.end());
}

template <class S>
const char* type_name() {
  return std::is_same_v<S, float> ? "float" : "double";
}

int kK = 16;       // --k
int kThreads = 0;  // --threads

// The options of the timed KNN searches: --k neighbours on --threads threads, the rest default.
smg::KnnOptions knn_options() {
  smg::KnnOptions o;
  o.k = kK;
  o.parallel.threads = kThreads;
  return o;
}

// The cost counters every KNN benchmark reports from its stats (the table at the top).
void knn_cost_counters(benchmark::State& state, const smg::KnnStats& st, Index N) {
  state.counters["pairs_per_node"] = static_cast<double>(st.pairs_evaluated) / static_cast<double>(N);
  state.counters["scratch_mb"] = static_cast<double>(st.scratch_bytes) / (1024.0 * 1024.0);
}

// ---- peak memory of a fresh process ---------------------------------------------------------
// The benchmark re-runs itself as `bench_graph --rss-probe N T float|double`: the child builds
// the scene and the KNN once and prints its ru_maxrss, so each figure starts from an empty process.
template <class S>
int rss_probe(Index N, Index T) {
  smg::test::SceneOptions o;
  o.nodes = N;
  o.frames = T;
  o.objects = 8;
  o.seed = 2024;
  const auto sc = smg::test::make_scene<S>(o);
  std::vector<std::int32_t> idx(static_cast<std::size_t>(N * kK));
  std::vector<S> dist(idx.size());
  smg::KnnOptions k;
  k.k = kK;
  const auto st = smg::trajectory_knn<S>({sc.positions.data(), T, N}, {sc.visibility.data(), T, N}, k,
                                         {idx.data(), N, kK}, {dist.data(), N, kK});
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  std::printf("%ld %zu\n", static_cast<long>(u.ru_maxrss), st.scratch_bytes);
  return 0;
}

double peak_rss_mb(Index N, Index T, const char* type) {
  char exe[4096] = {0};
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n <= 0) return std::nan("");
  const std::string cmd = std::string(exe) + " --rss-probe " + std::to_string(N) + " " + std::to_string(T) + " " + type;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return std::nan("");
  long kb = -1;
  std::size_t bytes = 0;
  const int got = std::fscanf(p, "%ld %zu", &kb, &bytes);
  pclose(p);
  return got == 2 ? static_cast<double>(kb) / 1024.0 : std::nan("");
}

// ---- exact KNN ------------------------------------------------------------------------------
template <class S>
void BM_knn(benchmark::State& state, Index N, Index T) {
  const auto& sc = scene({N, T, 0, 1.0});
  const auto x = cast<S>(sc.positions);
  const smg::PositionsView<const S> xv(x.data(), T, N);
  const smg::VisibilityView<const std::uint8_t> vv(sc.visibility.data(), T, N);
  const smg::KnnOptions o = knn_options();
  std::vector<std::int32_t> idx(static_cast<std::size_t>(N * kK));
  std::vector<S> dist(idx.size());
  smg::KnnStats st;
  for (auto _ : state) {
    st = smg::trajectory_knn<S>(xv, vv, o, {idx.data(), N, kK}, {dist.data(), N, kK});
    benchmark::DoNotOptimize(idx.data());
  }
  // Error columns (not timed): brute-force rows, in S and in double on the same inputs.
  const bool all = static_cast<double>(N) * static_cast<double>(N) * static_cast<double>(T) <= 2.5e9;
  std::vector<Index> rows;
  if (all) {
    for (Index i = 0; i < N; ++i) rows.push_back(i);
  } else {
    std::mt19937_64 g(7);
    for (int r = 0; r < 64; ++r) rows.push_back(static_cast<Index>(g() % static_cast<std::uint64_t>(N)));
  }
  smg::detail::TrajectoryStore<S> store;
  store.build(xv, vv, {});
  smg::detail::TrajectoryStore<double> store_d;
  const std::vector<double> xd(x.begin(), x.end());
  if (std::is_same_v<S, float>) store_d.build({xd.data(), T, N}, vv, {});
  std::vector<int> mismatch(rows.size(), 0), differ(rows.size(), 0);
  std::vector<double> rel(rows.size(), 0.0);
  smg::parallel_for(static_cast<Index>(rows.size()), [&](Index b, Index e) {
    std::vector<S> acc(3), bd(kK);
    std::vector<double> accd(3), bdd(kK);
    std::vector<std::int32_t> bj(kK), bjd(kK);
    int nb = 0, nbd = 0;
    for (Index r = b; r < e; ++r) {
      const Index i = rows[static_cast<std::size_t>(r)];
      smg::detail::TopK<S> top{bd.data(), bj.data(), &nb, kK};
      smg::detail::TopK<double> topd{bdd.data(), bjd.data(), &nbd, kK};
      top.reset();
      topd.reset();
      for (Index j = 0; j < N; ++j) {
        if (j == i) continue;
        const S d = smg::detail::pair_distance(store, i, j, o.distance, acc.data());
        if (d < std::numeric_limits<S>::infinity()) top.insert(d, static_cast<std::int32_t>(j));
        if (std::is_same_v<S, float>) {
          const double dd = smg::detail::pair_distance(store_d, i, j, o.distance, accd.data());
          if (dd < std::numeric_limits<double>::infinity()) topd.insert(dd, static_cast<std::int32_t>(j));
        }
      }
      for (int q = 0; q < kK; ++q) {
        const auto at = static_cast<std::size_t>(i * kK + q);
        const std::int32_t want = q < nb ? bj[static_cast<std::size_t>(q)] : -1;
        const S wd = q < nb ? bd[static_cast<std::size_t>(q)] : S(0);
        if (idx[at] != want || dist[at] != wd) mismatch[static_cast<std::size_t>(r)] = 1;
        if (std::is_same_v<S, float>) {
          const std::int32_t wantd = q < nbd ? bjd[static_cast<std::size_t>(q)] : -1;
          if (idx[at] != wantd) differ[static_cast<std::size_t>(r)] = 1;
          if (q < nbd && q < nb)
            rel[static_cast<std::size_t>(r)] =
                std::max(rel[static_cast<std::size_t>(r)],
                         std::abs(static_cast<double>(dist[at]) - bdd[static_cast<std::size_t>(q)]) /
                             std::max(bdd[static_cast<std::size_t>(q)], 1e-300));
        }
      }
    }
  });
  int mism = 0, diff = 0;
  double worst = 0;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    mism += mismatch[r];
    diff += differ[r];
    worst = std::max(worst, rel[r]);
  }
  state.counters["checked_rows"] = static_cast<double>(rows.size());
  state.counters["mismatched_rows"] = mism;
  if (std::is_same_v<S, float>) {
    state.counters["rows_differ_vs_f64"] = static_cast<double>(diff) / static_cast<double>(rows.size());
    state.counters["dist_rel_err_vs_f64"] = worst;
  }
  state.counters["segment_frames"] = st.segment_frames;
  knn_cost_counters(state, st, N);
  state.counters["input_mb"] = static_cast<double>(x.size() * sizeof(S) + sc.visibility.size()) / (1024.0 * 1024.0);
  state.counters["peak_rss_mb"] = peak_rss_mb(N, T, type_name<S>());
}

template <class S>
void BM_knn_brute_force(benchmark::State& state, Index N, Index T) {
  const auto& sc = scene({N, T, 0, 1.0});
  const auto x = cast<S>(sc.positions);
  const smg::KnnOptions o = knn_options();
  std::vector<std::int32_t> idx(static_cast<std::size_t>(N * kK));
  std::vector<S> dist(idx.size());
  smg::KnnStats st;
  for (auto _ : state) {
    st = smg::trajectory_knn_brute_force<S>({x.data(), T, N}, {sc.visibility.data(), T, N}, o, {idx.data(), N, kK},
                                            {dist.data(), N, kK});
    benchmark::DoNotOptimize(idx.data());
  }
  knn_cost_counters(state, st, N);
}

// Exact KNN with a fixed segment length (0 = automatic), on a fast and a slow scene.
void BM_knn_segments(benchmark::State& state, Index N, Index T, double speed, int L) {
  const auto& sc = scene({N, T, 0, speed});
  smg::KnnOptions o = knn_options();
  o.segment_frames = L;
  std::vector<std::int32_t> idx(static_cast<std::size_t>(N * kK));
  std::vector<double> dist(idx.size());
  smg::KnnStats st;
  for (auto _ : state) {
    st = smg::trajectory_knn<double>({sc.positions.data(), T, N}, {sc.visibility.data(), T, N}, o, {idx.data(), N, kK},
                                     {dist.data(), N, kK});
    benchmark::DoNotOptimize(idx.data());
  }
  state.counters["segment_frames"] = st.segment_frames;
  knn_cost_counters(state, st, N);
}

// ---- descriptors ----------------------------------------------------------------------------
template <class S>
void BM_descriptors(benchmark::State& state, Index N, Index T, Index C) {
  const auto& sc = scene({N, T, C, 1.0});
  const auto g = cast<S>(sc.samples);
  std::vector<S> f(static_cast<std::size_t>(N * C));
  smg::DescriptorOptions o;
  o.parallel.threads = kThreads;
  for (auto _ : state) {
    smg::semantic_descriptors<S>({g.data(), T, N, C}, {sc.visibility.data(), T, N}, o, {f.data(), N, C});
    benchmark::DoNotOptimize(f.data());
  }
  if (std::is_same_v<S, float>) {
    // Against double on the same (float-rounded) samples: the largest angle between descriptors.
    const std::vector<double> gd(g.begin(), g.end());
    std::vector<double> fd(f.size());
    smg::semantic_descriptors<double>({gd.data(), T, N, C}, {sc.visibility.data(), T, N}, o, {fd.data(), N, C});
    double worst = 0;
    for (Index i = 0; i < N; ++i) {
      double dot = 0;
      for (Index c = 0; c < C; ++c) dot += static_cast<double>(f[static_cast<std::size_t>(i * C + c)]) * fd[static_cast<std::size_t>(i * C + c)];
      worst = std::max(worst, std::acos(std::min(1.0, dot)));
    }
    state.counters["angle_err_vs_f64"] = worst;
  }
  state.counters["ns_per_sample"] = benchmark::Counter(
      static_cast<double>(state.iterations()) * static_cast<double>(N * T) * 1e-9,
      benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// ---- the whole graph ------------------------------------------------------------------------
template <class S>
void BM_graph(benchmark::State& state, Index N, Index T, Index C) {
  const auto& sc = scene({N, T, C, 1.0});
  const auto x = cast<S>(sc.positions);
  const auto g = cast<S>(sc.samples);
  std::vector<S> f(static_cast<std::size_t>(N * C));
  std::vector<std::int32_t> idx(static_cast<std::size_t>(N * kK));
  std::vector<S> w(idx.size()), d(idx.size());
  smg::GraphOptions o;
  o.knn = knn_options();
  smg::GraphStats st;
  for (auto _ : state) {
    smg::semantic_descriptors<S>({g.data(), T, N, C}, {sc.visibility.data(), T, N}, {}, {f.data(), N, C});
    st = smg::build_semantic_graph<S>({x.data(), T, N}, {sc.visibility.data(), T, N}, {f.data(), N, C}, o,
                                      {idx.data(), N, kK}, {w.data(), N, kK}, {d.data(), N, kK});
    benchmark::DoNotOptimize(idx.data());
  }
  // Edges that join different objects (the gate's job: only keep_nearest may leave some).
  Index cross = 0;
  for (Index i = 0; i < N; ++i)
    for (int q = 0; q < kK; ++q) {
      const std::int32_t j = idx[static_cast<std::size_t>(i * kK + q)];
      if (j >= 0 && sc.object[static_cast<std::size_t>(i)] != sc.object[static_cast<std::size_t>(j)]) ++cross;
    }
  state.counters["mean_degree"] = st.mean_degree;
  state.counters["gate_removed_frac"] =
      static_cast<double>(st.gate_removed_edges) / static_cast<double>(std::max<Index>(1, st.knn.neighbors));
  state.counters["cross_object_edges"] = static_cast<double>(cross);
  state.counters["isolated_nodes"] = static_cast<double>(st.isolated_nodes);
  state.counters["kept_nearest"] = static_cast<double>(st.kept_nearest);
}

// ---- adaptive node selection ----------------------------------------------------------------
void BM_node_selection(benchmark::State& state, Index N, Index T, double unit) {
  const auto& sc = scene({N, T, 0, 1.0});
  std::vector<std::int32_t> sel(static_cast<std::size_t>(N)), asg(sel.size());
  std::vector<double> err(sel.size());
  smg::NodeSelectionOptions o;
  o.parallel.threads = kThreads;
  o.unit = unit;
  smg::NodeSelectionStats<double> st;
  for (auto _ : state) {
    st = smg::select_nodes<double>({sc.positions.data(), T, N}, {sc.visibility.data(), T, N}, o, {sel.data(), N},
                                   {asg.data(), N}, {err.data(), N});
    benchmark::DoNotOptimize(sel.data());
  }
  state.counters["nodes"] = static_cast<double>(st.selected);
  state.counters["nodes_frac"] = static_cast<double>(st.selected) / static_cast<double>(std::max<Index>(1, st.eligible));
  state.counters["max_error"] = st.max_error;
  state.counters["mean_error"] = st.mean_error;
  state.counters["pairs_per_node"] = static_cast<double>(st.pairs_evaluated) / static_cast<double>(N);
}

bool smoke_run(int argc, char** argv) {
  for (int a = 1; a < argc; ++a) {
    const char* flag = "--benchmark_min_time=";
    if (std::strncmp(argv[a], flag, std::strlen(flag)) == 0) return std::atof(argv[a] + std::strlen(flag)) < 0.05;
  }
  return false;
}

int g_reps = 1;
template <class F>
void add(const std::string& name, F f, int iterations) {
  smg_bench::protocol(benchmark::RegisterBenchmark(name.c_str(), f)->Unit(benchmark::kMillisecond)->Iterations(iterations),
                      g_reps);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 5 && std::strcmp(argv[1], "--rss-probe") == 0) {
    const Index N = std::atol(argv[2]), T = std::atol(argv[3]);
    return std::strcmp(argv[4], "float") == 0 ? rss_probe<float>(N, T) : rss_probe<double>(N, T);
  }
  const bool smoke = smoke_run(argc, argv);
  smg_bench::Params p(argc, argv, "graph");
  const std::vector<long> n_list = p.list("n", smoke ? std::vector<long>{1000} : std::vector<long>{1000, 5000, 20000, 50000},
                                          "node counts N of the KNN rows");
  const std::vector<long> t_list = p.list("t", smoke ? std::vector<long>{100} : std::vector<long>{100, 400},
                                          "frame counts T of the KNN rows");
  kK = static_cast<int>(p.integer("k", 16, "neighbours K"));
  kThreads = static_cast<int>(p.integer("threads", 0, "ParallelOptions::threads (0: all hardware threads)"));
  p.precision();
  g_reps = p.reps(1);
  const Index dN = p.integer("descriptor_n", smoke ? 1000 : 20000, "N of the descriptor, graph and node-selection rows");
  const Index segN = p.integer("segments_n", smoke ? 1000 : 10000, "N of the segment-length rows");
  p.finish();
  const bool fl = p.runs<float>(), db = p.runs<double>();
  const std::vector<Index> sizes(n_list.begin(), n_list.end());
  const std::vector<Index> lengths(t_list.begin(), t_list.end());
  auto its = [](Index N) { return N <= 5000 ? 3 : 1; };
  for (Index T : lengths)
    for (Index N : sizes) {
      const std::string s = "/" + std::to_string(N) + "/" + std::to_string(T);
      if (db) add("knn/double" + s, [=](benchmark::State& st) { BM_knn<double>(st, N, T); }, its(N));
      if (fl) add("knn/float" + s, [=](benchmark::State& st) { BM_knn<float>(st, N, T); }, its(N));
      if (N <= 5000 && T == 100) {
        if (db) add("knn_brute_force/double" + s, [=](benchmark::State& st) { BM_knn_brute_force<double>(st, N, T); }, 1);
        if (fl) add("knn_brute_force/float" + s, [=](benchmark::State& st) { BM_knn_brute_force<float>(st, N, T); }, 1);
      }
    }
  for (double speed : {1.0, 0.1})
    for (int L : {0, 1, 2, 4, 8, 16, 32}) {
      const std::string s = "/" + std::to_string(segN) + "/100/speed" + (speed == 1.0 ? "1" : "0.1") + "/L" + std::to_string(L);
      if (db) add("knn_segments/double" + s, [=](benchmark::State& st) { BM_knn_segments(st, segN, 100, speed, L); }, 1);
    }
  for (Index C : {Index(8), Index(32)}) {
    const std::string s = "/" + std::to_string(dN) + "/100/" + std::to_string(C);
    if (db) add("descriptors/double" + s, [=](benchmark::State& st) { BM_descriptors<double>(st, dN, 100, C); }, 1);
    if (fl) add("descriptors/float" + s, [=](benchmark::State& st) { BM_descriptors<float>(st, dN, 100, C); }, 1);
    if (db) add("graph/double" + s, [=](benchmark::State& st) { BM_graph<double>(st, dN, 100, C); }, 1);
    if (fl) add("graph/float" + s, [=](benchmark::State& st) { BM_graph<float>(st, dN, 100, C); }, 1);
  }
  for (double unit : {0.02, 0.05, 0.1, 0.2, 0.4}) {
    char s[64];
    std::snprintf(s, sizeof s, "/%ld/100/unit%g", static_cast<long>(dN), unit);
    if (db) add(std::string("node_selection/double") + s, [=](benchmark::State& st) { BM_node_selection(st, dN, 100, unit); }, 1);
  }
  return smg_bench::run(argc, argv);
}
