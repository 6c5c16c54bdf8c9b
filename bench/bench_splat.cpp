// Reference CPU splatter: forward and forward + backward time against resolution, Gaussian
// count and threads (float), and error against speed for its knobs.
//
// Scene (fixed seed): a camera at the origin looking down +z (fx = fy = 0.9 W), G Gaussians
// uniformly in its frustum between depths 2 and 8, random rotations, anisotropic scales
// whose projected standard deviation at 320x240 has median 1.5 sqrt(100k / G) px (lognormal,
// sd 0.5; so 10k and 100k scenes cover the image alike), opacity logits N(0, 2), RGB in
// [0, 1], background grey. The 3D scene is the same at every resolution. Backward: random
// dL/dimage and dL/ddepth (the example trainer's RGB + expected-depth loss).
//
// Columns: wall time and process CPU time (all threads) of one call (bench_common.hpp).
// Parameters (flags or SMG_BENCH_*, --smg_help): --g=10000,100000 --width=160,320,640
// --threads=1,2 --knob_g --knob_width --knob_threads --precision --reps. Counters: visible
// (Gaussians drawn), isect_per_visible (tiles per drawn Gaussian), and for the knob runs
//   err_image    max |pixel - reference| over image, alpha and depth/8, reference = double,
//                16-px tiles, 3 sigma (the pinned configuration);
//   err_grad     ‖g - g_ref‖ / ‖g_ref‖ over every parameter gradient, same reference.
#include <benchmark/benchmark.h>

#include "bench_common.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include "smg/splat.hpp"

namespace {

namespace sp = smg::splat;
using smg::Index;

template <class S>
struct Scene {
  Index G = 0;
  std::vector<S> means, quats, log_scales, logits, colors;
  sp::GaussianParams<S> params() const {
    sp::GaussianParams<S> p;
    p.means = {means.data(), G};
    p.quats = {quats.data(), G};
    p.log_scales = {log_scales.data(), G};
    p.opacity_logits = {logits.data(), G};
    p.colors = {colors.data(), G, 3};
    return p;
  }
  template <class T>
  Scene<T> cast() const {
    auto c = [](const std::vector<S>& v) { return std::vector<T>(v.begin(), v.end()); };
    return Scene<T>{G, c(means), c(quats), c(log_scales), c(logits), c(colors)};
  }
};

const Scene<double>& scene(Index G) {
  static std::map<Index, Scene<double>> cache;
  auto it = cache.find(G);
  if (it != cache.end()) return it->second;
  Scene<double> s;
  s.G = G;
  std::mt19937_64 rng(1234 + static_cast<std::uint64_t>(G));
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> n(0, 1);
  const double f320 = 0.9 * 320;  // focal length at 320x240
  const double median_px = 1.5 * std::sqrt(100000.0 / double(G));
  for (Index i = 0; i < G; ++i) {
    const double z = 2 + 6 * u(rng);
    const double x = (u(rng) - 0.5) * 320 / f320 * z, y = (u(rng) - 0.5) * 240 / f320 * z;
    s.means.insert(s.means.end(), {x, y, z});
    double q[4] = {n(rng), n(rng), n(rng), n(rng)};
    const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (double c : q) s.quats.push_back(c / qn);
    const double sigma_px = median_px * std::exp(0.5 * n(rng));
    for (int k = 0; k < 3; ++k)
      s.log_scales.push_back(std::log(sigma_px * z / f320 * std::exp(0.3 * n(rng))));
    s.logits.push_back(2 * n(rng));
    for (int k = 0; k < 3; ++k) s.colors.push_back(u(rng));
  }
  return cache.emplace(G, std::move(s)).first->second;
}

template <class S>
sp::Camera<S> camera(int W, int H) {
  sp::Camera<S> c;
  c.fx = c.fy = S(0.9 * W);
  c.cx = S(0.5 * W);
  c.cy = S(0.5 * H);
  c.width = W;
  c.height = H;
  return c;
}

template <class S>
struct Run {
  std::vector<S> image, alpha, depth;
  std::vector<S> gimage, gdepth;
  std::vector<S> g_means, g_quats, g_scales, g_logits, g_colors;
  sp::RenderWorkspace<S> ws;
  S bg[3] = {S(0.5), S(0.5), S(0.5)};

  sp::RenderImages<S> images(int W, int H) {
    image.resize(std::size_t(W) * H * 3);
    alpha.resize(std::size_t(W) * H);
    depth.resize(std::size_t(W) * H);
    return {{image.data(), H, W, 3}, {alpha.data(), H, W}, {depth.data(), H, W}};
  }
  sp::RenderImageGrads<S> image_grads(int W, int H) {
    if (gimage.empty()) {
      std::mt19937_64 rng(99);
      std::uniform_real_distribution<double> u(-1, 1);
      for (std::size_t k = 0; k < std::size_t(W) * H * 3; ++k) gimage.push_back(S(u(rng)));
      for (std::size_t k = 0; k < std::size_t(W) * H; ++k) gdepth.push_back(S(0.1 * u(rng)));
    }
    return {{gimage.data(), H, W, 3}, {}, {gdepth.data(), H, W}};
  }
  sp::GaussianGrads<S> grads(Index G) {
    g_means.resize(std::size_t(3 * G));
    g_quats.resize(std::size_t(4 * G));
    g_scales.resize(std::size_t(3 * G));
    g_logits.resize(std::size_t(G));
    g_colors.resize(std::size_t(3 * G));
    sp::GaussianGrads<S> g;
    g.means = {g_means.data(), G};
    g.quats = {g_quats.data(), G};
    g.log_scales = {g_scales.data(), G};
    g.opacity_logits = {g_logits.data(), G};
    g.colors = {g_colors.data(), G, 3};
    return g;
  }
  // One forward (+ backward); returns false with a message when validation fails.
  bool once(const Scene<S>& s, int W, int H, const sp::SplatSettings<S>& set, bool backward,
            int threads, std::string* err) {
    const auto cam = camera<S>(W, H);
    const auto im = images(W, H);
    sp::SplatSettings<S> st = set;
    st.background = bg;
    if (smg::Status v = sp::validate_render(s.params(), cam, st, im, 3); !v) {
      *err = v.message();
      return false;
    }
    sp::render_forward<3>(s.params(), cam, st, ws, im, {threads, 0});
    if (backward) sp::render_backward<3>(s.params(), cam, st, ws, image_grads(W, H), grads(s.G), {threads, 0});
    return true;
  }
  std::vector<double> all_grads() const {
    std::vector<double> out;
    for (const auto* v : {&g_means, &g_quats, &g_scales, &g_logits, &g_colors})
      out.insert(out.end(), v->begin(), v->end());
    return out;
  }
};

// Process CPU time (all threads) is the `cpu` column of every row (bench_common.hpp).
void common_counters(benchmark::State& state, Index visible, Index isect) {
  state.counters["visible"] = double(visible);
  state.counters["isect_per_visible"] = visible ? double(isect) / double(visible) : 0.0;
}

// args: W, H, G, threads
template <bool kBackward>
void BM_splat(benchmark::State& state) {
  const int W = int(state.range(0)), H = int(state.range(1)), threads = int(state.range(3));
  const auto s = scene(state.range(2)).cast<float>();
  Run<float> run;
  std::string err;
  if (!run.once(s, W, H, {}, kBackward, threads, &err)) {
    state.SkipWithError(err.c_str());
    return;
  }
  for (auto _ : state) {
    run.once(s, W, H, {}, kBackward, threads, &err);
    benchmark::DoNotOptimize(run.image.data());
  }
  common_counters(state, run.ws.n_visible, run.ws.n_isect);
}

// Reference for the knob runs: double, 16-px tiles, 3 sigma, forward + backward.
const Run<double>& reference(int W, int H, Index G) {
  static std::map<std::tuple<int, int, Index>, Run<double>> cache;
  const auto key = std::make_tuple(W, H, G);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  Run<double>& r = cache[key];
  std::string err;
  r.once(scene(G), W, H, {}, true, 2, &err);
  return r;
}

// args: W, H, G, threads, tile size, 10 x radius sigmas
template <class S>
void BM_splat_knobs(benchmark::State& state) {
  const int W = int(state.range(0)), H = int(state.range(1)), threads = int(state.range(3));
  const Index G = state.range(2);
  sp::SplatSettings<S> set;
  set.tile_size = int(state.range(4));
  set.radius_sigmas = S(double(state.range(5)) / 10);
  const auto s = scene(G).template cast<S>();
  Run<S> run;
  std::string err;
  if (!run.once(s, W, H, set, true, threads, &err)) {
    state.SkipWithError(err.c_str());
    return;
  }
  const Run<double>& ref = reference(W, H, G);
  double err_image = 0;
  for (std::size_t k = 0; k < ref.image.size(); ++k)
    err_image = std::max(err_image, std::abs(double(run.image[k]) - ref.image[k]));
  for (std::size_t k = 0; k < ref.alpha.size(); ++k) {
    err_image = std::max(err_image, std::abs(double(run.alpha[k]) - ref.alpha[k]));
    err_image = std::max(err_image, std::abs(double(run.depth[k]) - ref.depth[k]) / 8);
  }
  const auto g = run.all_grads(), gr = ref.all_grads();
  double num = 0, den = 0;
  for (std::size_t k = 0; k < gr.size(); ++k) {
    num += (g[k] - gr[k]) * (g[k] - gr[k]);
    den += gr[k] * gr[k];
  }
  for (auto _ : state) {
    run.once(s, W, H, set, true, threads, &err);
    benchmark::DoNotOptimize(run.image.data());
  }
  common_counters(state, run.ws.n_visible, run.ws.n_isect);
  state.counters["err_image"] = err_image;
  state.counters["err_grad"] = std::sqrt(num / den);
}

// Run-time parameters (main()).
std::vector<long> g_threads{1, 2}, g_counts{10000, 100000}, g_widths{160, 320, 640};
long g_knob_g = 100000, g_knob_w = 320, g_knob_threads = 2;
int g_reps = 1;

void sizes(benchmark::internal::Benchmark* b) {
  for (long threads : g_threads)
    for (long G : g_counts)
      for (long w : g_widths) b->Args({w, w * 3 / 4, G, threads});
  b->ArgNames({"W", "H", "G", "threads"})->Unit(benchmark::kMillisecond);
  smg_bench::protocol(b, g_reps);
}

void knobs(benchmark::internal::Benchmark* b) {
  for (int tile : {8, 16, 32}) b->Args({g_knob_w, g_knob_w * 3 / 4, g_knob_g, g_knob_threads, tile, 30});
  b->Args({g_knob_w, g_knob_w * 3 / 4, g_knob_g, g_knob_threads, 16, 25});
  b->ArgNames({"W", "H", "G", "threads", "tile", "sigmas_x10"})->Unit(benchmark::kMillisecond);
  smg_bench::protocol(b, g_reps);
}

}  // namespace

int main(int argc, char** argv) {
  smg_bench::Params p(argc, argv, "splat");
  g_counts = p.list("g", g_counts, "Gaussian counts of the size rows");
  g_widths = p.list("width", g_widths, "image widths of the size rows (height = 3/4 width)");
  g_threads = p.list("threads", g_threads, "thread counts of the size rows");
  g_knob_g = p.integer("knob_g", g_knob_g, "Gaussians of the knob rows");
  g_knob_w = p.integer("knob_width", g_knob_w, "image width of the knob rows");
  g_knob_threads = p.integer("knob_threads", g_knob_threads, "threads of the knob rows");
  p.precision();
  g_reps = p.reps(1);
  p.finish();
  if (p.runs<float>()) {
    benchmark::RegisterBenchmark("forward", BM_splat<false>)->Apply(sizes);
    benchmark::RegisterBenchmark("forward_backward", BM_splat<true>)->Apply(sizes);
    benchmark::RegisterBenchmark("knobs_float", BM_splat_knobs<float>)->Apply(knobs);
  }
  if (p.runs<double>()) {
    auto* b = benchmark::RegisterBenchmark("knobs_double", BM_splat_knobs<double>)
                  ->Args({g_knob_w, g_knob_w * 3 / 4, g_knob_g, g_knob_threads, 16, 30})
                  ->ArgNames({"W", "H", "G", "threads", "tile", "sigmas_x10"})
                  ->Unit(benchmark::kMillisecond);
    smg_bench::protocol(b, g_reps);
  }
  return smg_bench::run(argc, argv);
}
