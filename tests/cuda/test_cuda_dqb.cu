// Tests of smg/cuda/dqb.cuh: smg::cuda::skin_blend and skin_blend_backward against the CPU
// smg::skin_blend / smg::skin_blend_backward on random and hard cases (double within 1e-12 of
// the largest magnitude of each output, float within 1e-5), two GPU runs bit-identical, query
// frames out of range (NaN outputs, skipped in the backward), the in-edge lists that
// build_driver_incidence and build_reverse_graph build on the device against the host
// construction, and the host-side validation.
#include <algorithm>
#include <doctest/doctest.h>

#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "smg/cuda/dqb.cuh"
#include "smg/skin/blend.hpp"
#include "support/random.hpp"

#include "cuda/cuda_test_support.cuh"

namespace {

using smg::Index;
using namespace smg::test::cuda;

// A skinning problem in double (cast to the scalar of the run).
struct DqbCase : CaseSizes {
  std::vector<double> xn, qn;          // [T][N][3], [T][N][4] (not normalised)
  std::vector<std::int32_t> drivers;   // [P][D]
  std::vector<double> weights;         // [P][D]
  std::vector<std::int32_t> t_ref;     // [P]
  std::vector<double> points, pquats;  // [P][3], [P][4] or empty
  std::vector<std::int32_t> t_query;   // [Q]
  smg::SkinMethod method = smg::SkinMethod::dqb;
};

// Random nodes (quaternions of random norm in [0.5, 2] and random sign), points with 1..D
// distinct drivers (−1 padding after), positive weights (some zero, never all), optional point
// quaternions, and query frames with repeats.
DqbCase random_case(const std::string& name, Index T, Index N, Index P, Index D, Index Q,
                    std::uint64_t seed, bool point_quats) {
  smg::test::Rng rng(seed);
  DqbCase c;
  static_cast<CaseSizes&>(c) = {name, T, N, 0, P, D};
  for (Index k = 0; k < T * N; ++k) {
    const smg::Vector3<double> x = rng.vec3(2.0);
    c.xn.insert(c.xn.end(), {x(0), x(1), x(2)});
    const smg::Quaternion<double> q = rng.quaternion();
    const double s = rng.uniform(0.5, 2.0) * (rng.uniform() < 0 ? -1.0 : 1.0);
    c.qn.insert(c.qn.end(), {s * q.w(), s * q.x(), s * q.y(), s * q.z()});
  }
  c.drivers.assign(static_cast<std::size_t>(P * D), -1);
  c.weights.assign(static_cast<std::size_t>(P * D), 0.0);
  for (Index p = 0; p < P; ++p) {
    const Index deg = std::min<Index>(N, rng.integer(1, int(D)));
    std::vector<std::int32_t> perm(static_cast<std::size_t>(N));
    for (Index n = 0; n < N; ++n) perm[static_cast<std::size_t>(n)] = std::int32_t(n);
    std::shuffle(perm.begin(), perm.end(), rng.engine);
    for (Index k = 0; k < deg; ++k) {
      c.drivers[static_cast<std::size_t>(p * D + k)] = perm[static_cast<std::size_t>(k)];
      c.weights[static_cast<std::size_t>(p * D + k)] =
          (k > 0 && rng.uniform() < -0.6) ? 0.0 : rng.uniform(0.05, 1.0);
    }
    c.t_ref.push_back(std::int32_t(rng.integer(0, int(T) - 1)));
    const smg::Vector3<double> x = rng.vec3(2.0);
    c.points.insert(c.points.end(), {x(0), x(1), x(2)});
    if (point_quats) {
      const smg::Quaternion<double> q = rng.quaternion();
      const double s = rng.uniform(0.5, 2.0);
      c.pquats.insert(c.pquats.end(), {s * q.w(), s * q.x(), s * q.y(), s * q.z()});
    }
  }
  for (Index q = 0; q < Q; ++q) c.t_query.push_back(std::int32_t(rng.integer(0, int(T) - 1)));
  return c;
}


// The arrays of one run, in S.
template <class S>
struct Arrays {
  std::vector<S> pos, quat, Jd, Jp;                             // forward
  std::vector<S> gxn, grn, gqn, gpts, gprot, gpq, gw;           // backward (added to a start)
};

constexpr int kArrays = 11;
const char* const kNames[kArrays] = {"positions",        "quaternions",        "J_drivers",
                                     "J_point",          "grad_node_positions", "grad_node_rotations",
                                     "grad_node_quaternions", "grad_points",   "grad_point_rotations",
                                     "grad_point_quaternions", "grad_weights"};
template <class S>
std::vector<S>* array(Arrays<S>& a, int i) {
  std::vector<S>* p[kArrays] = {&a.pos, &a.quat, &a.Jd, &a.Jp, &a.gxn, &a.grn,
                                &a.gqn, &a.gpts, &a.gprot, &a.gpq, &a.gw};
  return p[i];
}

// Output gradients dL/d(outputs) and the start values of the gradient buffers (random: the
// functions add to them).
template <class S>
struct Inputs {
  std::vector<S> go_pos, go_rot, go_quat;
  Arrays<S> start;
};
template <class S>
Inputs<S> make_inputs(const DqbCase& c) {
  smg::test::Rng rng(7);
  const Index Q = Index(c.t_query.size());
  auto fill = [&](std::size_t n) {
    std::vector<S> v(n);
    for (auto& x : v) x = S(rng.uniform());
    return v;
  };
  Inputs<S> in;
  in.go_pos = fill(static_cast<std::size_t>(Q * c.P * 3));
  in.go_rot = fill(static_cast<std::size_t>(Q * c.P * 3));
  in.go_quat = fill(static_cast<std::size_t>(Q * c.P * 4));
  in.start.gxn = fill(static_cast<std::size_t>(c.T * c.N * 3));
  in.start.grn = fill(static_cast<std::size_t>(c.T * c.N * 3));
  in.start.gqn = fill(static_cast<std::size_t>(c.T * c.N * 4));
  in.start.gpts = fill(static_cast<std::size_t>(c.P * 3));
  in.start.gprot = fill(static_cast<std::size_t>(c.P * 3));
  in.start.gpq = fill(static_cast<std::size_t>(c.pquats.empty() ? 0 : c.P * 4));
  in.start.gw = fill(static_cast<std::size_t>(c.P * c.D));
  return in;
}

// Views of one case over given storage (host or device pointers alike).
template <class S>
struct Views {
  smg::SkinNodes<S> nodes;
  smg::SkinPoints<S> points;
  smg::SkinIndexView t_query;
};
template <class S>
Views<S> views(const DqbCase& c, const S* xn, const S* qn, const std::int32_t* drv, const S* w,
               const std::int32_t* tref, const S* pts, const S* pq, const std::int32_t* tq) {
  Views<S> v;
  v.nodes.positions = smg::PositionsView<const S>(xn, c.T, c.N);
  v.nodes.quaternions = smg::QuaternionsView<const S>(qn, c.T, c.N);
  v.points.drivers = smg::SkinDriversView(drv, c.P, c.D);
  v.points.weights = smg::TableView<const S, Eigen::Dynamic>(w, c.P, c.D);
  v.points.t_ref = smg::SkinIndexView(tref, c.P);
  v.points.positions = smg::TableView<const S, 3>(pts, c.P);
  if (!c.pquats.empty()) v.points.quaternions = smg::TableView<const S, 4>(pq, c.P);
  v.t_query = smg::SkinIndexView(tq, Index(c.t_query.size()));
  return v;
}

template <class S>
smg::SkinBlendOutputs<S> outputs(const DqbCase& c, Arrays<S>& a) {
  const Index Q = Index(c.t_query.size());
  smg::SkinBlendOutputs<S> o;
  o.positions = smg::SequenceView<S, 3>(a.pos.data(), Q, c.P);
  o.quaternions = smg::SequenceView<S, 4>(a.quat.data(), Q, c.P);
  o.J_drivers = smg::SequenceView<S, Eigen::Dynamic>(a.Jd.data(), Q, c.P, c.D * 78);
  o.J_point = smg::SequenceView<S, Eigen::Dynamic>(a.Jp.data(), Q, c.P, 36);
  return o;
}
template <class S>
smg::SkinBlendGradients<S> gradients(const DqbCase& c, Arrays<S>& a) {
  smg::SkinBlendGradients<S> g;
  g.node_positions = smg::PositionsView<S>(a.gxn.data(), c.T, c.N);
  g.node_rotations = smg::TangentsView<S>(a.grn.data(), c.T, c.N);
  g.node_quaternions = smg::QuaternionsView<S>(a.gqn.data(), c.T, c.N);
  g.points = smg::TableView<S, 3>(a.gpts.data(), c.P);
  g.point_rotations = smg::TableView<S, 3>(a.gprot.data(), c.P);
  if (!c.pquats.empty()) g.point_quaternions = smg::TableView<S, 4>(a.gpq.data(), c.P);
  g.weights = smg::TableView<S, Eigen::Dynamic>(a.gw.data(), c.P, c.D);
  return g;
}
template <class S>
smg::SkinBlendOutputGradients<S> output_gradients(const DqbCase& c, const Inputs<S>& in,
                                                  const S* pos, const S* rot, const S* quat) {
  const Index Q = Index(c.t_query.size());
  (void)in;
  smg::SkinBlendOutputGradients<S> g;
  g.positions = smg::SequenceView<const S, 3>(pos, Q, c.P);
  g.rotations = smg::SequenceView<const S, 3>(rot, Q, c.P);
  g.quaternions = smg::SequenceView<const S, 4>(quat, Q, c.P);
  return g;
}

template <class S>
void size_forward(const DqbCase& c, Arrays<S>& a) {
  const std::size_t QP = c.t_query.size() * static_cast<std::size_t>(c.P);
  a.pos.assign(QP * 3, S(0));
  a.quat.assign(QP * 4, S(0));
  a.Jd.assign(QP * static_cast<std::size_t>(c.D * 78), S(-7));  // padding columns must be zeroed
  a.Jp.assign(QP * 36, S(0));
}

template <class S>
Arrays<S> run_cpu(const DqbCase& c, const Inputs<S>& in) {
  const auto xn = cast<S>(c.xn), qn = cast<S>(c.qn), w = cast<S>(c.weights),
             pts = cast<S>(c.points), pq = cast<S>(c.pquats);
  const Views<S> v = views<S>(c, xn.data(), qn.data(), c.drivers.data(), w.data(), c.t_ref.data(),
                              pts.data(), pq.data(), c.t_query.data());
  smg::SkinOptions opt;
  opt.method = c.method;
  Arrays<S> a = in.start;
  size_forward(c, a);
  smg::skin_blend<S>(v.nodes, v.points, v.t_query, outputs(c, a), opt);
  smg::SkinWorkspace<S> ws;
  smg::skin_blend_backward<S>(
      v.nodes, v.points, v.t_query,
      output_gradients<S>(c, in, in.go_pos.data(), in.go_rot.data(), in.go_quat.data()),
      gradients(c, a), ws, opt);
  return a;
}

template <class S>
Arrays<S> run_gpu(const DqbCase& c, const Inputs<S>& in) {
  Stream st;
  DeviceArray<S> xn(cast<S>(c.xn)), qn(cast<S>(c.qn)), w(cast<S>(c.weights)),
      pts(cast<S>(c.points)), pq(cast<S>(c.pquats));
  DeviceArray<std::int32_t> drv(c.drivers), tref(c.t_ref), tq(c.t_query);
  DeviceArray<S> go_pos(in.go_pos), go_rot(in.go_rot), go_quat(in.go_quat);
  const Views<S> v = views<S>(c, xn.get(), qn.get(), drv.get(), w.get(), tref.get(), pts.get(),
                              pq.get(), tq.get());
  smg::SkinOptions opt;
  opt.method = c.method;
  Arrays<S> host;
  size_forward(c, host);
  // Device copies of every array (forward outputs, and the gradient start values).
  DeviceArray<S> dev[kArrays];
  for (int i = 0; i < kArrays; ++i) {
    const std::vector<S>& src = i < 4 ? *array(host, i) : *array(const_cast<Arrays<S>&>(in.start), i);
    dev[i].upload(src);
  }
  Arrays<S> d;
  smg::SkinBlendOutputs<S> o;
  const Index Q = Index(c.t_query.size());
  o.positions = smg::SequenceView<S, 3>(dev[0].get(), Q, c.P);
  o.quaternions = smg::SequenceView<S, 4>(dev[1].get(), Q, c.P);
  o.J_drivers = smg::SequenceView<S, Eigen::Dynamic>(dev[2].get(), Q, c.P, c.D * 78);
  o.J_point = smg::SequenceView<S, Eigen::Dynamic>(dev[3].get(), Q, c.P, 36);
  smg::SkinBlendGradients<S> g;
  g.node_positions = smg::PositionsView<S>(dev[4].get(), c.T, c.N);
  g.node_rotations = smg::TangentsView<S>(dev[5].get(), c.T, c.N);
  g.node_quaternions = smg::QuaternionsView<S>(dev[6].get(), c.T, c.N);
  g.points = smg::TableView<S, 3>(dev[7].get(), c.P);
  g.point_rotations = smg::TableView<S, 3>(dev[8].get(), c.P);
  if (!c.pquats.empty()) g.point_quaternions = smg::TableView<S, 4>(dev[9].get(), c.P);
  g.weights = smg::TableView<S, Eigen::Dynamic>(dev[10].get(), c.P, c.D);

  smg::Status s = smg::cuda::skin_blend<S>(v.nodes, v.points, v.t_query, o, opt, st.s);
  REQUIRE_MESSAGE(s.is_ok(), s.message());
  smg::cuda::ReverseGraph inc;
  s = smg::cuda::build_driver_incidence(drv.get(), c.P, c.D, c.N, st.s, inc);
  REQUIRE_MESSAGE(s.is_ok(), s.message());
  s = smg::cuda::skin_blend_backward<S>(
      v.nodes, v.points, v.t_query,
      output_gradients<S>(c, in, go_pos.get(), go_rot.get(), go_quat.get()), g, inc, opt, st.s);
  REQUIRE_MESSAGE(s.is_ok(), s.message());
  st.sync();
  SMG_TEST_CUDA(cudaGetLastError());
  for (int i = 0; i < kArrays; ++i) *array(d, i) = dev[i].download();
  return d;
}

template <class S>
void compare(const DqbCase& c) {
  const std::string tag = c.name + (c.method == smg::SkinMethod::dqb ? " dqb" : " lbs") +
                          (sizeof(S) == 8 ? " [double]" : " [float]");
  CAPTURE(tag);
  const Inputs<S> in = make_inputs<S>(c);
  Arrays<S> cpu = run_cpu<S>(c, in);
  Arrays<S> a = run_gpu<S>(c, in), b = run_gpu<S>(c, in);
  // A node or weight gradient is a sum over points whose terms can cancel (static nodes, a single
  // driver: the exact value is 0 or ~1e-16). Its round-off is relative to the terms, not to the
  // sum, so the gradients (i >= 4) are compared against the largest gradient (or start value,
  // which both sides add to) of the case.
  double gradient_scale = 1e-30;
  for (int i = 4; i < kArrays; ++i) {
    const std::vector<S>& start = *array(const_cast<Arrays<S>&>(in.start), i);
    const std::vector<S>& out = *array(cpu, i);
    // Both sides add to the same start values, so they round at the start's magnitude too.
    for (std::size_t k = 0; k < out.size(); ++k)
      gradient_scale = std::max({gradient_scale, std::abs(double(out[k]) - double(start[k])),
                                 std::abs(double(start[k]))});
  }
  for (int i = 0; i < kArrays; ++i) {
    std::vector<double> dg(array(a, i)->size()), dc(array(cpu, i)->size());
    // Gradients (i >= 4) are compared after removing the start value.
    const std::vector<S>* start = i >= 4 ? array(const_cast<Arrays<S>&>(in.start), i) : nullptr;
    for (std::size_t k = 0; k < dg.size(); ++k)
      dg[k] = double((*array(a, i))[k]) - (start ? double((*start)[k]) : 0.0);
    for (std::size_t k = 0; k < dc.size(); ++k)
      dc[k] = double((*array(cpu, i))[k]) - (start ? double((*start)[k]) : 0.0);
    check_close(dg, dc, tolerance<S>(), tag + " " + kNames[i], i >= 4 ? gradient_scale : 1e-30);
    check_bitwise(*array(a, i), *array(b, i), tag + " " + kNames[i]);
  }
}

// The rows [Q][P][dim] of `a` for the queries in `keep`.
template <class S>
std::vector<S> query_rows(const std::vector<S>& a, Index Q, const std::vector<Index>& keep) {
  const std::size_t row = Q > 0 ? a.size() / static_cast<std::size_t>(Q) : 0;
  std::vector<S> r;
  for (const Index q : keep)
    r.insert(r.end(), a.begin() + std::ptrdiff_t(std::size_t(q) * row),
             a.begin() + std::ptrdiff_t(std::size_t(q + 1) * row));
  return r;
}

// `c` with query frames outside [0, T) inserted: on the GPU their forward outputs are NaN and
// the backward skips them, so the rest equals the CPU run on c.
template <class S>
void compare_bad_queries(DqbCase c) {
  const std::string tag = std::string(c.method == smg::SkinMethod::dqb ? "dqb" : "lbs") +
                          (sizeof(S) == 8 ? " [double]" : " [float]");
  CAPTURE(tag);
  DqbCase bad = c;
  bad.t_query.insert(bad.t_query.begin() + 1, -1);
  bad.t_query.push_back(std::int32_t(c.T));
  bad.t_query.push_back(std::int32_t(1) << 30);
  const Index Qb = Index(bad.t_query.size());
  std::vector<Index> good, skipped;
  for (Index q = 0; q < Qb; ++q)
    (bad.t_query[static_cast<std::size_t>(q)] >= 0 && bad.t_query[static_cast<std::size_t>(q)] < c.T
         ? good
         : skipped)
        .push_back(q);
  REQUIRE(Index(good.size()) == Index(c.t_query.size()));
  const Inputs<S> in_bad = make_inputs<S>(bad);
  Inputs<S> in = in_bad;  // the same output gradients for the good queries
  in.go_pos = query_rows(in_bad.go_pos, Qb, good);
  in.go_rot = query_rows(in_bad.go_rot, Qb, good);
  in.go_quat = query_rows(in_bad.go_quat, Qb, good);
  Arrays<S> cpu = run_cpu<S>(c, in);
  Arrays<S> gpu = run_gpu<S>(bad, in_bad);
  double gradient_scale = 1e-30;
  for (int i = 4; i < kArrays; ++i)
    for (const S v : *array(cpu, i)) gradient_scale = std::max(gradient_scale, std::abs(double(v)));
  for (int i = 0; i < kArrays; ++i) {
    const std::vector<S>& g = *array(gpu, i);
    if (i < 4) {
      check_close(query_rows(g, Qb, good), *array(cpu, i), tolerance<S>(), tag + " " + kNames[i]);
      bool nan = true;
      for (const S v : query_rows(g, Qb, skipped)) nan = nan && v != v;
      CHECK_MESSAGE(nan, tag << " " << kNames[i] << ": a query frame out of range gives NaN");
    } else {
      check_close(g, *array(cpu, i), tolerance<S>(), tag + " " + kNames[i], gradient_scale);
    }
  }
}

// A random table [rows][width] over `nodes` targets (−1 padding, entries out of range, a heavy
// target 0) through build_driver_incidence (or build_reverse_graph when rows == nodes), twice:
// offsets and entries equal the host construction and the two builds.
template <class I>
void check_device_in_edges(Index rows, Index width, Index nodes, std::uint64_t seed) {
  CAPTURE(rows);
  CAPTURE(width);
  CAPTURE(nodes);
  CAPTURE(sizeof(I));
  smg::test::Rng rng(seed);
  std::vector<I> table(static_cast<std::size_t>(rows * width));
  for (auto& v : table) {
    const double u = rng.uniform(0, 1);
    v = u < 0.15 ? I(-1)
        : u < 0.2 ? I(nodes + rng.integer(0, 2))
        : u < 0.25 ? I(-2 - rng.integer(0, 2))
        : u < 0.5 ? I(0)
                  : I(rng.integer(0, int(nodes) - 1));
  }
  std::vector<std::int32_t> off_ref;
  std::vector<std::int64_t> ent_ref;
  host_in_edges(table, nodes, off_ref, ent_ref);
  Stream st;
  DeviceArray<I> d(table);
  for (int run = 0; run < 2; ++run) {
    smg::cuda::ReverseGraph g;
    const smg::Status s =
        rows == nodes && run == 1
            ? smg::cuda::build_reverse_graph(d.get(), nodes, width, st.s, g)
            : smg::cuda::build_driver_incidence(d.get(), rows, width, nodes, st.s, g);
    REQUIRE_MESSAGE(s.is_ok(), s.message());
    CHECK(g.nodes == nodes);
    CHECK(g.k == width);
    st.sync();
    std::vector<std::int32_t> off(static_cast<std::size_t>(nodes + 1));
    SMG_TEST_CUDA(cudaMemcpy(off.data(), g.offsets.get(), off.size() * sizeof(std::int32_t),
                             cudaMemcpyDeviceToHost));
    std::vector<std::int64_t> ent(static_cast<std::size_t>(off.back()));
    if (!ent.empty())
      SMG_TEST_CUDA(cudaMemcpy(ent.data(), g.entries.get(), ent.size() * sizeof(std::int64_t),
                               cudaMemcpyDeviceToHost));
    CHECK(off == off_ref);
    CHECK(ent == ent_ref);
  }
}

void compare_all(DqbCase c) {
  for (const smg::SkinMethod m : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
    c.method = m;
    compare<double>(c);
    compare<float>(c);
  }
}

}  // namespace

TEST_CASE("cuda dqb: random cases match the CPU forward, Jacobians and backward") {
  struct Cfg {
    Index T, N, P, D, Q;
    bool pq;
  };
  const Cfg cfgs[] = {{4, 20, 150, 4, 3, true},  {3, 30, 200, 8, 2, false}, {5, 40, 100, 12, 2, true},
                      {2, 40, 80, 17, 1, true},   {3, 50, 60, 32, 2, false}, {1, 3, 10, 1, 1, true}};
  std::uint64_t seed = 100;
  for (const Cfg& f : cfgs) {
    std::ostringstream n;
    n << "random T=" << f.T << " N=" << f.N << " P=" << f.P << " D=" << f.D << " Q=" << f.Q
      << " seed=" << seed;
    compare_all(random_case(n.str(), f.T, f.N, f.P, f.D, f.Q, seed++, f.pq));
  }
}

TEST_CASE("cuda dqb: hard cases (antipodal quaternions, single drivers, zero weights, shared nodes)") {
  // Antipodal: every node's quaternion at odd frames is the negated one of frame 0 (same
  // rotation), and half the drivers' motions point away from the pivot's (sign alignment).
  DqbCase c = random_case("antipodal", 4, 12, 120, 5, 4, 201, true);
  for (Index t = 1; t < c.T; ++t)
    for (Index n = 0; n < c.N; ++n)
      for (int k = 0; k < 4; ++k)
        c.qn[static_cast<std::size_t>((t * c.N + n) * 4 + k)] =
            (t % 2 ? -1.0 : 1.5) * c.qn[static_cast<std::size_t>(n * 4 + k)];
  compare_all(c);
  // Exactly opposite quaternion signs between neighbouring nodes in one frame.
  c = random_case("antipodal nodes", 3, 8, 60, 4, 2, 202, false);
  for (Index t = 0; t < c.T; ++t)
    for (Index n = 1; n < c.N; n += 2)
      for (int k = 0; k < 4; ++k)
        c.qn[static_cast<std::size_t>((t * c.N + n) * 4 + k)] =
            -c.qn[static_cast<std::size_t>((t * c.N + n - 1) * 4 + k)];
  compare_all(c);
  // One driver per point (D = 1), and every point on the same two nodes (long gathers).
  compare_all(random_case("single driver", 3, 10, 80, 1, 2, 203, true));
  c = random_case("two shared nodes", 3, 2, 500, 2, 3, 204, true);
  compare_all(c);
  // Zero weights on all but the first driver (and equal weights: pivot ties, first wins).
  c = random_case("zero and tied weights", 3, 20, 100, 6, 2, 205, true);
  for (Index p = 0; p < c.P; ++p)
    for (Index k = 0; k < c.D; ++k) {
      double& w = c.weights[static_cast<std::size_t>(p * c.D + k)];
      if (c.drivers[static_cast<std::size_t>(p * c.D + k)] < 0) continue;
      w = (p % 2 == 0) ? (k == 0 ? 1.0 : 0.0) : 0.5;
    }
  compare_all(c);
  // Identity motions (every frame the same pose): blended rotation = identity ⊗ q_p.
  c = random_case("static nodes", 3, 10, 50, 4, 3, 206, true);
  for (Index t = 1; t < c.T; ++t)
    for (Index n = 0; n < c.N; ++n) {
      for (int k = 0; k < 3; ++k)
        c.xn[static_cast<std::size_t>((t * c.N + n) * 3 + k)] = c.xn[static_cast<std::size_t>(n * 3 + k)];
      for (int k = 0; k < 4; ++k)
        c.qn[static_cast<std::size_t>((t * c.N + n) * 4 + k)] = c.qn[static_cast<std::size_t>(n * 4 + k)];
    }
  compare_all(c);
}

TEST_CASE("cuda dqb: query frames out of range give NaN outputs and add nothing to the gradients") {
  for (const smg::SkinMethod m : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
    DqbCase c = random_case("bad queries", 3, 15, 90, 5, 3, 401, true);
    c.method = m;
    compare_bad_queries<double>(c);
    compare_bad_queries<float>(c);
  }
}

TEST_CASE("cuda in-edges: build_driver_incidence and build_reverse_graph equal the host construction") {
  check_device_in_edges<std::int32_t>(300, 17, 25, 501);    // driver table, rows > nodes
  check_device_in_edges<std::int64_t>(300, 9, 25, 502);
  check_device_in_edges<std::int32_t>(7, 32, 600, 503);     // rows < nodes, nodes > scan threads
  check_device_in_edges<std::int64_t>(40, 16, 40, 504);     // a graph: rows == nodes
  check_device_in_edges<std::int32_t>(2000, 17, 300, 505);  // long lists (target 0: ~8500 edges)
}

TEST_CASE("cuda dqb: validation before launch") {
  Stream st;
  DqbCase c = random_case("validation", 2, 6, 10, 3, 2, 301, false);
  DeviceArray<double> xn(c.xn), qn(c.qn), w(c.weights), pts(c.points), out(std::vector<double>(
                                                                           c.t_query.size() * 10 * 3));
  DeviceArray<std::int32_t> drv(c.drivers), tref(c.t_ref), tq(c.t_query);
  const Views<double> v = views<double>(c, xn.get(), qn.get(), drv.get(), w.get(), tref.get(),
                                        pts.get(), nullptr, tq.get());
  smg::SkinBlendOutputs<double> o;
  o.positions = smg::SequenceView<double, 3>(out.get(), Index(c.t_query.size()), c.P - 1);
  smg::Status s = smg::cuda::skin_blend<double>(v.nodes, v.points, v.t_query, o, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("out_positions") != std::string::npos);

  Views<double> bad = v;
  bad.points.weights = smg::TableView<const double, Eigen::Dynamic>(w.get(), c.P, c.D - 1);
  s = smg::cuda::skin_blend<double>(bad.nodes, bad.points, bad.t_query, {}, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("weights") != std::string::npos);

  // Node gradients need an incidence built for this table.
  DeviceArray<double> gx(std::vector<double>(c.xn.size(), 0.0));
  smg::SkinBlendGradients<double> g;
  g.node_positions = smg::PositionsView<double>(gx.get(), c.T, c.N);
  smg::cuda::ReverseGraph none;
  s = smg::cuda::skin_blend_backward<double>(v.nodes, v.points, v.t_query, {}, g, none, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("incidence") != std::string::npos);

  // D above the kernels' maximum.
  const Index D = smg::cuda::kSkinMaxD + 1;
  std::vector<std::int32_t> big(static_cast<std::size_t>(c.P * D), -1);
  for (Index p = 0; p < c.P; ++p) big[static_cast<std::size_t>(p * D)] = 0;
  DeviceArray<std::int32_t> bdrv(big);
  DeviceArray<double> bw(std::vector<double>(big.size(), 0.0));
  Views<double> vb = v;
  vb.points.drivers = smg::SkinDriversView(bdrv.get(), c.P, D);
  vb.points.weights = smg::TableView<const double, Eigen::Dynamic>(bw.get(), c.P, D);
  s = smg::cuda::skin_blend<double>(vb.nodes, vb.points, vb.t_query, {}, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("D=33") != std::string::npos);
  st.sync();
}
