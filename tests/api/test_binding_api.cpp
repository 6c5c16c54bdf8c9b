// Tests of the binding-ready API (docs/conventions.md "Rotation gradients", "Graph indices",
// "Threads and executors"): raw-quaternion gradients against central differences in both
// directions of the converter and through every energy and the DQB backward, int64 graph
// indices giving the same bits as int32, a caller's executor giving the same bits as smg's pool
// for any thread count, and the fixed-capacity gap list.
#include <doctest/doctest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "energy/scene.hpp"
#include "smg/smg.hpp"
#include "support/finite_diff.hpp"
#include "support/operators.hpp"
#include "support/random.hpp"

using smg::Index;
using smg::test::relative_error;

namespace {

// Scene quaternions scaled away from unit length, so that raw gradients see |q| != 1.
smg::test::Scene<double> unnormalised_scene(smg::test::Rng& rng, Index T, Index N, Index K) {
  smg::test::Scene<double> s = smg::test::random_scene(T, N, K, rng);
  for (Index k = 0; k < T * N; ++k) {
    const double f = rng.uniform(0.5, 2.0);
    for (int c = 0; c < 4; ++c) s.q[k * 4 + c] *= f;
  }
  s.c.assign(static_cast<std::size_t>(T * N), 0.0);
  for (auto& c : s.c) c = rng.uniform(0, 1);
  return s;
}

// f(q) = a·R(q̂) v + b·R(q̂) w: a smooth function of the normalised rotation.
double rotation_function(const Eigen::Vector4d& q, const Eigen::Vector3d& a,
                         const Eigen::Vector3d& b, const Eigen::Vector3d& v,
                         const Eigen::Vector3d& w) {
  const smg::Quaternion<double> r = smg::from_wxyz(q).normalized();
  return a.dot(r * v) + b.dot(r * w);
}

// Runs every operator of the list (support/operators.hpp) on `in` and appends to `out` its
// energy, position and rotation gradients (or updates) and confidences, each into zeroed buffers.
template <class I>
void run_operators(const smg::test::OperatorInputs<double, I>& in, smg::EnergyWorkspace<double>* ws,
                   smg::ParallelOptions po, std::vector<double>& out) {
  const Index T = in.positions.frames(), N = in.positions.nodes();
  smg::test::for_each_operator([&](auto op) {
    const std::string op_name = op.name;  // doctest CAPTUREs a const char* as a pointer
    CAPTURE(op_name);
    std::vector<double> gx(T * N * 3, 0.0), gr(T * N * 3, 0.0), c(T * N, 0.0);
    out.push_back(op.run(in, {{gx.data(), T, N}, {gr.data(), T, N}, {c.data(), T, N}}, ws, po));
    out.insert(out.end(), gx.begin(), gx.end());
    out.insert(out.end(), gr.begin(), gr.end());
    out.insert(out.end(), c.begin(), c.end());
  });
}

}  // namespace

TEST_CASE("raw <-> tangent rotation gradient converters agree with central differences") {
  SMG_TEST_RNG(rng, 101);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Vector3d a = rng.vec3(), b = rng.vec3(), v = rng.vec3(), w = rng.vec3();
    Eigen::Vector4d q = smg::to_wxyz(rng.quaternion()) * rng.uniform(0.3, 3.0);
    if (trial == 0) q = Eigen::Vector4d(0, 1e-3, -2, 0.5);  // w = 0: a half-turn, unnormalised
    auto f = [&](const Eigen::VectorXd& x) {
      return Eigen::VectorXd::Constant(1, rotation_function(x, a, b, v, w));
    };
    // Raw gradient by central differences on the 4 coordinates.
    const Eigen::VectorXd g_raw_fd = smg::test::central_jacobian(f, q, 1e-6).transpose();
    // Tangent gradient by central differences of q̂ ⊗ Exp(φ).
    const smg::Quaternion<double> qhat = smg::from_wxyz(Eigen::Vector4d(q)).normalized();
    auto fp = [&](const Eigen::VectorXd& phi) {
      const smg::Quaternion<double> r = qhat * smg::so3::exp(Eigen::Vector3d(phi));
      return Eigen::VectorXd::Constant(1, rotation_function(smg::to_wxyz(r), a, b, v, w));
    };
    const Eigen::VectorXd g_phi_fd = smg::test::central_jacobian_perturbed(fp, 3).transpose();

    Eigen::Vector4d g_raw = Eigen::Vector4d::Zero();
    smg::add_quaternion_gradient_from_tangent(q.data(), g_phi_fd.data(), g_raw.data());
    CHECK(relative_error(g_raw, g_raw_fd) < 1e-7);
    Eigen::Vector3d g_phi = Eigen::Vector3d::Zero();
    smg::add_tangent_gradient_from_quaternion(q.data(), g_raw_fd.data(), g_phi.data());
    CHECK(relative_error(g_phi, g_phi_fd) < 1e-7);
    // The raw gradient of a function of q̂ is orthogonal to q; a radial component is ignored.
    CHECK(std::abs(g_raw.dot(q)) < 1e-12 * g_raw.norm() * q.norm() + 1e-300);
    Eigen::Vector3d g_phi2 = Eigen::Vector3d::Zero();
    const Eigen::Vector4d radial = g_raw_fd + 3.7 * q;
    smg::add_tangent_gradient_from_quaternion(q.data(), radial.data(), g_phi2.data());
    CHECK(relative_error(g_phi2, g_phi_fd) < 1e-7);
  }
}

TEST_CASE("batched converters equal the per-element ones and add to their output") {
  smg::test::Rng rng(7);
  const Index T = 3, N = 5;
  std::vector<double> q(T * N * 4), gt(T * N * 3), gq(T * N * 4);
  for (auto& x : q) x = rng.normal();
  for (auto& x : gt) x = rng.normal();
  for (auto& x : gq) x = rng.normal();
  std::vector<double> raw(T * N * 4, 1.0), tan(T * N * 3, -1.0);
  smg::quaternion_gradient_from_tangent<double>({q.data(), T, N}, {gt.data(), T, N},
                                                {raw.data(), T, N});
  smg::tangent_gradient_from_quaternion<double>({q.data(), T, N}, {gq.data(), T, N},
                                                {tan.data(), T, N});
  for (Index k = 0; k < T * N; ++k) {
    double r[4] = {1, 1, 1, 1}, t[3] = {-1, -1, -1};
    smg::add_quaternion_gradient_from_tangent(&q[k * 4], &gt[k * 3], r);
    smg::add_tangent_gradient_from_quaternion(&q[k * 4], &gq[k * 4], t);
    for (int c = 0; c < 4; ++c) CHECK(raw[k * 4 + c] == r[c]);
    for (int c = 0; c < 3; ++c) CHECK(tan[k * 3 + c] == t[c]);
  }
}

TEST_CASE("C-ARAP and ARAP raw-quaternion gradients agree with central differences") {
  SMG_TEST_RNG(rng, 202);
  const Index T = 6, N = 7, K = 3;
  smg::test::Scene<double> s = unnormalised_scene(rng, T, N, K);
  smg::CarapOptions co;
  co.gaps = {{1, 1.0}, {2, 0.5}};
  smg::ArapOptions ao;
  ao.gaps = co.gaps;
  for (int which = 0; which < 2; ++which) {
    CAPTURE(which);
    auto energy = [&](const std::vector<double>& q) {
      smg::QuaternionsView<const double> Q(q.data(), T, N);
      return which == 0 ? smg::carap<double>(s.positions(), Q, s.confidence(), s.graph(), co)
                        : smg::arap<double>(s.positions(), Q, s.graph(), ao);
    };
    std::vector<double> g_raw(T * N * 4, 0.0), g_tan(T * N * 3, 0.0), g_x(T * N * 3, 0.0);
    smg::QuaternionsView<double> raw_view(g_raw.data(), T, N);
    smg::TangentsView<double> tan_view(g_tan.data(), T, N);
    smg::PositionsView<double> gx_view(g_x.data(), T, N);
    if (which == 0) {
      REQUIRE(smg::validate_carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(),
                                          co, gx_view, raw_view));
      smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), co, gx_view,
                         raw_view);
      smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), co, {},
                         tan_view);
    } else {
      REQUIRE(smg::validate_arap<double>(s.positions(), s.rotations(), s.graph(), ao, {},
                                         raw_view));
      smg::arap<double>(s.positions(), s.rotations(), s.graph(), ao, {}, raw_view);
      smg::arap<double>(s.positions(), s.rotations(), s.graph(), ao, {}, tan_view);
    }
    // Central differences on every raw coordinate.
    std::vector<double> fd(T * N * 4);
    for (Index k = 0; k < T * N * 4; ++k) {
      std::vector<double> qp = s.q, qm = s.q;
      const double h = 1e-6;
      qp[k] += h;
      qm[k] -= h;
      fd[k] = (energy(qp) - energy(qm)) / (2 * h);
    }
    const Eigen::Map<const Eigen::VectorXd> A(g_raw.data(), T * N * 4), B(fd.data(), T * N * 4);
    CHECK(relative_error(A, B) < 1e-7);
    // The raw output is the converter applied to the tangent output.
    std::vector<double> converted(T * N * 4, 0.0);
    smg::quaternion_gradient_from_tangent<double>(s.rotations(), {g_tan.data(), T, N},
                                                  {converted.data(), T, N});
    const Eigen::Map<const Eigen::VectorXd> C(converted.data(), T * N * 4);
    CHECK(relative_error(A, C) < 1e-14);
  }
}

TEST_CASE("int64 graph indices give the same bits as int32, without a copy") {
  smg::test::Rng rng(404);
  const Index T = 9, N = 40, K = 5;
  smg::test::Scene<double> s = unnormalised_scene(rng, T, N, K);
  // Short rows (padding) as well.
  for (Index k = K - 1; k < N * K; k += 3 * K) {
    s.idx[k] = -1;
    s.w[k] = 0;
  }
  std::vector<std::int64_t> idx64(s.idx.begin(), s.idx.end());
  const smg::NeighborsView<double, std::int64_t> g64(idx64.data(), s.w.data(), N, K);
  const smg::NeighborsView<double> g32 = s.graph();
  CHECK(g64.indices.data() == idx64.data());  // read in place
  REQUIRE(smg::validate_neighbors(g64, N));
  auto run = [&](const auto& g) {
    std::vector<double> c(T * N), out;
    smg::node_confidences<double>(s.positions(), s.visibility(), g, smg::ConfidenceOptions{},
                                  {c.data(), T, N});
    const smg::FrameScalarsView<const double> C(c.data(), T, N);
    run_operators(smg::test::inputs_of(s, g, C), nullptr, {}, out);
    smg::CarapResidualBlock<double> b;
    REQUIRE(smg::carap_residual_block<double>(s.positions(), s.rotations(), C, g,
                                              smg::CarapOptions{}, 0, 2, 3, 0, b));
    out.insert(out.end(), b.r.data(), b.r.data() + 4);
    out.insert(out.end(), c.begin(), c.end());
    std::vector<std::int32_t> anchor = {0, 5, 17}, drv(3 * (K + 1));
    smg::skin_drivers(g, {anchor.data(), 3}, {drv.data(), 3, K + 1});
    out.insert(out.end(), drv.begin(), drv.end());
    return out;
  };
  const std::vector<double> a = run(g32), b = run(g64);
  REQUIRE(a.size() == b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    CAPTURE(k);
    REQUIRE(a[k] == b[k]);
  }
  // Validation reads int64 values beyond int32 as they are (no wrap-around).
  idx64[3] = (std::int64_t(1) << 32) + 3;
  const smg::Status st = smg::validate_neighbors(g64, N);
  CHECK_FALSE(st);
  CHECK(st.message().find("out of range: 4294967299") != std::string::npos);
}

namespace {
// A caller's executor for the tests: runs the jobs on `threads` std::threads, handing them out
// in reverse order (so any dependence of results on execution order would show).
std::atomic<int> g_executor_calls{0};
void reverse_executor(void*, Index count, int threads, void (*job)(void*, Index), void* ctx) {
  ++g_executor_calls;
  std::atomic<Index> next{count - 1};
  auto worker = [&] {
    for (Index c; (c = next.fetch_sub(1)) >= 0;) job(ctx, c);
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
}
// An executor that runs every job on the calling thread (at::parallel_for does that when it is
// itself called from inside a parallel region).
void inline_executor(void*, Index count, int, void (*job)(void*, Index), void* ctx) {
  ++g_executor_calls;
  for (Index c = 0; c < count; ++c) job(ctx, c);
}
}  // namespace

TEST_CASE("a caller's executor gives the same bits as smg's pool for any thread count") {
  smg::test::Rng rng(505);
  const Index T = 40, N = 300, K = 6;
  smg::test::Scene<double> s = unnormalised_scene(rng, T, N, K);
  auto run = [&](smg::ParallelOptions po) {
    std::vector<double> c(T * N), out;
    smg::EnergyWorkspace<double> ws;
    smg::node_confidences<double>(s.positions(), s.visibility(), s.graph(),
                                  smg::ConfidenceOptions{}, {c.data(), T, N}, {}, {}, &ws, po);
    run_operators(smg::test::inputs_of(s, s.graph(), smg::FrameScalarsView<const double>(c.data(), T, N)), &ws, po,
                  out);
    out.insert(out.end(), c.begin(), c.end());
    return out;
  };
  const std::vector<double> ref = run(smg::ParallelOptions{1});
  for (int threads : {2, 3, 7}) {
    CAPTURE(threads);
    CHECK(run(smg::ParallelOptions{threads}) == ref);
    g_executor_calls = 0;
    {
      const smg::ScopedExecutor scoped({reverse_executor, nullptr});
      CHECK(run(smg::ParallelOptions{threads}) == ref);
    }
    CHECK(g_executor_calls > 0);
    const smg::ScopedExecutor scoped({inline_executor, nullptr});
    CHECK(run(smg::ParallelOptions{threads}) == ref);
  }
  // The process-wide executor applies unless a ScopedExecutor on this thread says otherwise;
  // a scoped Executor{} means smg's own pool.
  smg::set_executor(smg::Executor{reverse_executor, nullptr});
  g_executor_calls = 0;
  CHECK(run(smg::ParallelOptions{3}) == ref);
  CHECK(g_executor_calls > 0);
  {
    const smg::ScopedExecutor own_pool(smg::Executor{});
    g_executor_calls = 0;
    CHECK(run(smg::ParallelOptions{3}) == ref);
    CHECK(g_executor_calls == 0);
  }
  smg::set_executor({});
  g_executor_calls = 0;
  CHECK(run(smg::ParallelOptions{3}) == ref);
  CHECK(g_executor_calls == 0);
}

TEST_CASE("an exception inside a chunk run by a caller's executor reaches the caller") {
  int seen = 0;
  const auto run = [&] {
    const smg::ScopedExecutor scoped({reverse_executor, nullptr});
    smg::parallel_for_chunks(
        100,
        [&](Index c, Index, Index) {
          if (c == 37) throw std::runtime_error("chunk 37");
        },
        smg::ParallelOptions{4, 1});
  };
  try {
    run();
  } catch (const std::runtime_error& e) {
    seen = std::string(e.what()) == "chunk 37" ? 1 : 2;
  }
  CHECK(seen == 1);
}

TEST_CASE("gap lists: a fixed capacity, plain values, and validation of an overflow") {
  static_assert(std::is_trivially_copyable_v<smg::GapList>);
  static_assert(std::is_trivially_copyable_v<smg::CarapOptions>);
  static_assert(std::is_trivially_copyable_v<smg::LrmOptions>);
  static_assert(std::is_trivially_copyable_v<smg::ConfidenceOptions>);
  smg::CarapOptions o;
  CHECK(o.gaps.size() == 3);
  CHECK(o.gaps[2].delta == 4);
  CHECK(smg::validate_options(o));
  o.gaps.clear();
  for (int d = 1; d <= 9; ++d) o.gaps.push_back({d, 1.0});
  CHECK(o.gaps.size() == smg::GapList::kCapacity);
  const smg::Status st = smg::validate_options(o);
  CHECK_FALSE(st);
  CHECK(st.message() == "CarapOptions.gaps: more than 8 gaps");
  const std::vector<smg::Gap> v = {{1, 1.0}, {3, 0.5}};
  const smg::GapList from_vector(v.begin(), v.end());
  CHECK(from_vector.size() == 2);
  CHECK(from_vector[1].weight == 0.5);
}
