// Tests of smg/cuda/skin_weights.cuh: smg::cuda::skin_drivers against the CPU smg::skin_drivers
// (bit for bit) and smg::cuda::skinning_weights against the CPU smg::skinning_weights (double
// within 1e-12 of the largest weight, float within 1e-5) on random graphs (int32 and int64
// indices, empty rows, K + 1 up to 32 drivers), points far from their drivers (softmax underflow)
// and the fallback (S4); two GPU runs bit-identical; and the host-side shape checks (suite
// cuda-host: they return before any launch, so they also run without a GPU).
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "smg/cuda/skin_weights.cuh"
#include "smg/skin/drivers.hpp"
#include "smg/skin/weights.hpp"
#include "support/random.hpp"

#include "cuda/cuda_test_support.cuh"

namespace {

using smg::Index;
using namespace smg::test::cuda;

// A random problem in double: positions [T][N][3], a graph [N][K] (random degree 0..K, distinct
// neighbours, no self edges, −1 padded), anchors [P], t_ref [P], points [P][3] near their anchor
// (scaled by `spread`), sigma [N] in [sigma_lo, 2 sigma_lo].
struct WeightsCase : CaseSizes {
  std::vector<double> x, gw, points, sigma;
  std::vector<std::int64_t> idx;
  std::vector<std::int32_t> anchor, t_ref;
};

WeightsCase random_case(const std::string& name, Index T, Index N, Index K, Index P,
                        std::uint64_t seed, double spread = 1.0, double sigma_lo = 0.3) {
  smg::test::Rng rng(seed);
  WeightsCase c;
  static_cast<CaseSizes&>(c) = {name, T, N, K, P};
  for (Index k = 0; k < T * N; ++k) {
    const smg::Vector3<double> v = rng.vec3(2.0);
    c.x.insert(c.x.end(), {v(0), v(1), v(2)});
  }
  c.idx.assign(static_cast<std::size_t>(N * K), -1);
  c.gw.assign(static_cast<std::size_t>(N * K), 0.0);
  for (Index i = 0; i < N; ++i) {
    std::vector<std::int64_t> others;
    for (Index j = 0; j < N; ++j)
      if (j != i) others.push_back(j);
    std::shuffle(others.begin(), others.end(), rng.engine);
    const Index deg = std::min<Index>(Index(others.size()), rng.integer(0, int(K)));
    for (Index k = 0; k < deg; ++k) {
      c.idx[static_cast<std::size_t>(i * K + k)] = others[static_cast<std::size_t>(k)];
      c.gw[static_cast<std::size_t>(i * K + k)] = rng.uniform(0.1, 1.0);
    }
  }
  for (Index p = 0; p < P; ++p) {
    const std::int32_t a = std::int32_t(rng.integer(0, int(N) - 1));
    const std::int32_t tr = std::int32_t(rng.integer(0, int(T) - 1));
    c.anchor.push_back(a);
    c.t_ref.push_back(tr);
    const std::size_t o = static_cast<std::size_t>((tr * N + a) * 3);
    const smg::Vector3<double> v = rng.vec3(spread);
    c.points.insert(c.points.end(), {c.x[o] + v(0), c.x[o + 1] + v(1), c.x[o + 2] + v(2)});
  }
  for (Index n = 0; n < N; ++n) c.sigma.push_back(rng.uniform(sigma_lo, 2 * sigma_lo));
  return c;
}


template <class S, class I>
void run_case(const WeightsCase& c) {
  CAPTURE(c.name);
  CAPTURE(sizeof(S));
  CAPTURE(sizeof(I));
  const Index T = c.T, N = c.N, K = c.K, P = c.P, D = K + 1;
  const std::vector<S> x = cast<S>(c.x), gw = cast<S>(c.gw), pts = cast<S>(c.points),
                       sg = cast<S>(c.sigma);
  const std::vector<I> idx(c.idx.begin(), c.idx.end());

  // CPU.
  std::vector<std::int32_t> drv_cpu(static_cast<std::size_t>(P * D));
  std::vector<S> w_cpu(static_cast<std::size_t>(P * D));
  const smg::NeighborsView<S, I> g_cpu(idx.data(), gw.data(), N, K);
  const smg::SkinIndexView a_cpu(c.anchor.data(), P), tr_cpu(c.t_ref.data(), P);
  const smg::TableView<std::int32_t, Eigen::Dynamic> dv_cpu(drv_cpu.data(), P, D);
  REQUIRE(smg::validate_skin_drivers(g_cpu, a_cpu, N, dv_cpu).is_ok());
  smg::skin_drivers(g_cpu, a_cpu, dv_cpu);
  const smg::PositionsView<const S> x_cpu(x.data(), T, N);
  const smg::TableView<const S, 3> p_cpu(pts.data(), P);
  const smg::TableView<const S, 1> s_cpu(sg.data(), N);
  const smg::TableView<S, Eigen::Dynamic> wv_cpu(w_cpu.data(), P, D);
  REQUIRE(smg::validate_skinning_weights<S>(x_cpu, dv_cpu, tr_cpu, p_cpu, s_cpu, wv_cpu).is_ok());
  smg::skinning_weights<S>(x_cpu, dv_cpu, tr_cpu, p_cpu, s_cpu, wv_cpu);

  // GPU, twice.
  Stream st;
  DeviceArray<S> d_x(x), d_gw(gw), d_pts(pts), d_sg(sg);
  DeviceArray<I> d_idx(idx);
  DeviceArray<std::int32_t> d_anchor(c.anchor), d_tref(c.t_ref);
  std::vector<std::int32_t> drv_gpu[2];
  std::vector<S> w_gpu[2];
  for (int run = 0; run < 2; ++run) {
    DeviceArray<std::int32_t> d_drv(std::vector<std::int32_t>(static_cast<std::size_t>(P * D), 7));
    DeviceArray<S> d_w(std::vector<S>(static_cast<std::size_t>(P * D), S(3)));
    const smg::NeighborsView<S, I> g(d_idx.get(), d_gw.get(), N, K);
    const smg::TableView<std::int32_t, Eigen::Dynamic> dv(d_drv.get(), P, D);
    const smg::Status s1 =
        smg::cuda::skin_drivers(g, smg::SkinIndexView(d_anchor.get(), P), dv, st.s);
    REQUIRE_MESSAGE(s1.is_ok(), s1.message());
    const smg::Status s2 = smg::cuda::skinning_weights<S>(
        smg::PositionsView<const S>(d_x.get(), T, N), smg::SkinDriversView(d_drv.get(), P, D),
        smg::SkinIndexView(d_tref.get(), P), smg::TableView<const S, 3>(d_pts.get(), P),
        smg::TableView<const S, 1>(d_sg.get(), N),
        smg::TableView<S, Eigen::Dynamic>(d_w.get(), P, D), st.s);
    REQUIRE_MESSAGE(s2.is_ok(), s2.message());
    st.sync();
    drv_gpu[run] = d_drv.download();
    w_gpu[run] = d_w.download();
  }
  check_bitwise(drv_gpu[0], drv_cpu, c.name + ": drivers, gpu vs cpu");
  check_close(w_gpu[0], w_cpu, tolerance<S>(), c.name + ": weights");
  check_bitwise(drv_gpu[0], drv_gpu[1], c.name + ": drivers");
  check_bitwise(w_gpu[0], w_gpu[1], c.name + ": weights");
}

template <class S>
void run_both_index_types(const WeightsCase& c) {
  run_case<S, std::int32_t>(c);
  run_case<S, std::int64_t>(c);
}

}  // namespace

TEST_CASE("cuda skin_drivers and skinning_weights: random cases match the CPU") {
  const WeightsCase cases[] = {
      random_case("small", 3, 9, 4, 50, 11),
      random_case("K=7 (D=8)", 2, 40, 7, 700, 12),
      random_case("K=12 (D=13)", 4, 60, 12, 1000, 13),
      random_case("K=31 (D=32)", 2, 50, 31, 600, 14),
      random_case("K=0 (anchor only)", 2, 6, 0, 30, 15),
      random_case("one node", 2, 1, 3, 20, 16),
      random_case("no points", 2, 5, 3, 0, 17),
  };
  for (const auto& c : cases) {
    run_both_index_types<double>(c);
    run_both_index_types<float>(c);
  }
}

TEST_CASE("cuda skinning_weights: far points (softmax underflow) and the fallback (S4)") {
  // Points 1e3 sigmas from their drivers: every exp underflows, the softmax still normalises.
  const WeightsCase far = random_case("far", 2, 30, 6, 300, 21, 300.0, 0.3);
  run_both_index_types<double>(far);
  run_both_index_types<float>(far);
  // Every other point 1e300 away: ‖p − x‖/σ overflows for every driver, all weight on the
  // anchor (double only: 1e300 is not a float).
  WeightsCase fb = random_case("fallback", 2, 20, 5, 200, 22);
  for (std::size_t k = 0; k < fb.points.size(); ++k)
    if (k % 6 < 3) fb.points[k] += 1e300;  // the even points
  run_case<double, std::int32_t>(fb);
  run_case<double, std::int64_t>(fb);
}

TEST_SUITE("cuda-host") {
  TEST_CASE("cuda skin_drivers and skinning_weights: shapes are checked before launch") {
    using V = smg::TableView<std::int32_t, Eigen::Dynamic>;
    const smg::NeighborsView<double, std::int32_t> g(nullptr, nullptr, 4, 3);
    std::int32_t dummy[64] = {};
    double dd[64] = {};
    auto msg = [](const smg::Status& s) { return s.is_ok() ? std::string("ok") : s.message(); };
    // A null graph, a null anchor, a wrong driver table.
    CHECK(msg(smg::cuda::skin_drivers(g, smg::SkinIndexView(dummy, 2), V(dummy, 2, 4), nullptr))
              .find("graph: null data pointer") != std::string::npos);
    const smg::NeighborsView<double, std::int32_t> g2(dummy, dd, 4, 3);
    CHECK(msg(smg::cuda::skin_drivers(g2, smg::SkinIndexView(nullptr, 2), V(dummy, 2, 4), nullptr))
              .find("anchor: null data pointer") != std::string::npos);
    CHECK(msg(smg::cuda::skin_drivers(g2, smg::SkinIndexView(dummy, 2), V(dummy, 2, 3), nullptr))
              .find("drivers: expected shape [P=2][K+1=4], got [2][3]") != std::string::npos);
    // P = 0: ok without a launch.
    CHECK(msg(smg::cuda::skin_drivers(g2, smg::SkinIndexView(dummy, 0), V(dummy, 0, 4), nullptr)) ==
          "ok");

    using W = smg::TableView<double, Eigen::Dynamic>;
    const smg::PositionsView<const double> x(dd, 2, 4);
    const smg::TableView<const double, 3> pts(dd, 3);
    const smg::TableView<const double, 1> sg(dd, 4);
    const smg::SkinDriversView drv(dummy, 3, 5);
    const smg::SkinIndexView tr(dummy, 3);
    auto weights = [&](smg::PositionsView<const double> xv, smg::SkinDriversView dv,
                       smg::SkinIndexView tv, smg::TableView<const double, 3> pv,
                       smg::TableView<const double, 1> sv, W wv) {
      return msg(smg::cuda::skinning_weights<double>(xv, dv, tv, pv, sv, wv, nullptr));
    };
    CHECK(weights(x, smg::SkinDriversView(dummy, 3, 0), tr, pts, sg, W(dd, 3, 0))
              .find("drivers: expected shape [P=3][D>=1], got [3][0]") != std::string::npos);
    CHECK(weights(x, smg::SkinDriversView(dummy, 3, 33), tr, pts, sg, W(dd, 3, 33))
              .find("exceeds the CUDA skinning kernels' maximum of 32") != std::string::npos);
    CHECK(weights(x, drv, smg::SkinIndexView(dummy, 2), pts, sg, W(dd, 3, 5))
              .find("t_ref: expected 3 entries, got 2") != std::string::npos);
    CHECK(weights(x, drv, tr, smg::TableView<const double, 3>(dd, 2), sg, W(dd, 3, 5))
              .find("points: expected shape [P=3][3], got [2][3]") != std::string::npos);
    CHECK(weights(x, drv, tr, pts, smg::TableView<const double, 1>(dd, 3), W(dd, 3, 5))
              .find("sigma: expected shape [N=4][1], got [3][1]") != std::string::npos);
    CHECK(weights(x, drv, tr, pts, sg, W(dd, 3, 4))
              .find("weights: expected shape [P=3][D=5], got [3][4]") != std::string::npos);
    CHECK(weights(x, drv, tr, pts, sg, W(nullptr, 3, 5)).find("weights: null data pointer") !=
          std::string::npos);
    CHECK(weights(smg::PositionsView<const double>(nullptr, 2, 4), drv, tr, pts, sg, W(dd, 3, 5))
              .find("positions: null data pointer") != std::string::npos);
    CHECK(weights(x, smg::SkinDriversView(dummy, 0, 5), smg::SkinIndexView(dummy, 0),
                  smg::TableView<const double, 3>(dd, 0), sg, W(dd, 0, 5)) == "ok");
  }
}
