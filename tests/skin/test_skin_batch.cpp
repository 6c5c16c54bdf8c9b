// Tests of the batched skinning functions (smg/skin/drivers.hpp, weights.hpp, blend.hpp):
// agreement with the per-point kernels, the backward against a dense serial reference and
// against central differences of the whole pipeline (weights included), bit-identical results
// for 1, 2 and 7 threads, and validation messages.
#include <doctest/doctest.h>

#include <cstring>
#include <functional>
#include <utility>
#include <vector>

#include "skin/skin_test_support.hpp"
#include "support/prelude.hpp"

using smg::SkinMethod;
using smg::test::SkinScene;

namespace {

constexpr SkinMethod kMethods[] = {SkinMethod::dqb, SkinMethod::lbs};

// Everything derived from a SkinScene: drivers, weights, views.
struct Setup {
  SkinScene s;
  Index D = 0, Q = 0;
  std::vector<std::int32_t> drivers, t_query;
  std::vector<double> weights;
  bool with_point_quats = true;

  smg::SkinNodes<double> nodes() const {
    return {{s.positions.data(), s.T, s.N}, {s.quats.data(), s.T, s.N}};
  }
  smg::SkinPoints<double> points() const {
    smg::SkinPoints<double> p;
    p.drivers = {drivers.data(), s.P, D};
    p.weights = {weights.data(), s.P, D};
    p.t_ref = {s.t_ref.data(), s.P};
    p.positions = {s.points.data(), s.P};
    if (with_point_quats) p.quaternions = {s.point_quats.data(), s.P};
    return p;
  }
  smg::SkinIndexView query() const { return {t_query.data(), Q}; }
  smg::NeighborsView<double> graph() const {
    return {s.graph_idx.data(), s.graph_w.data(), s.N, s.K};
  }
  void compute_weights() {
    weights.assign(static_cast<std::size_t>(s.P * D), -1.0);
    smg::skinning_weights<double>({s.positions.data(), s.T, s.N}, {drivers.data(), s.P, D},
                                  {s.t_ref.data(), s.P}, {s.points.data(), s.P},
                                  {s.sigma.data(), s.N}, {weights.data(), s.P, D});
  }
};

Setup make_setup(smg::test::Rng& rng, Index T, Index N, Index K, Index P, Index Q) {
  Setup u;
  u.s = smg::test::random_scene(rng, T, N, K, P);
  u.D = K + 1;
  u.Q = Q;
  for (Index q = 0; q < Q; ++q) u.t_query.push_back(rng.integer(0, int(T) - 1));
  u.drivers.assign(static_cast<std::size_t>(P * u.D), 0);
  smg::skin_drivers(u.graph(), {u.s.anchor.data(), P}, {u.drivers.data(), P, u.D});
  u.compute_weights();
  return u;
}

// The per-point drivers of point p at query frame t, gathered and normalised by hand.
smg::test::Drivers gather(const Setup& u, Index p, Index t) {
  smg::test::Drivers d;
  auto quat = [&](Index tt, Index n) {
    const double* c = &u.s.quats[(tt * u.s.N + n) * 4];
    return Quaternion<double>(c[0], c[1], c[2], c[3]).normalized();
  };
  const Index tr = u.s.t_ref[p];
  for (Index k = 0; k < u.D; ++k) {
    const std::int32_t n = u.drivers[p * u.D + k];
    if (n < 0) break;
    smg::SkinDriver<double> x;
    x.x_ref = Eigen::Map<const Vector3<double>>(&u.s.positions[(tr * u.s.N + n) * 3]);
    x.x_t = Eigen::Map<const Vector3<double>>(&u.s.positions[(t * u.s.N + n) * 3]);
    x.q_ref = quat(tr, n);
    x.q_t = quat(t, n);
    x.weight = u.weights[p * u.D + k];
    d.push_back(x);
  }
  return d;
}
Quaternion<double> point_quat(const Setup& u, Index p) {
  if (!u.with_point_quats) return Quaternion<double>::Identity();
  const double* c = &u.s.point_quats[p * 4];
  return Quaternion<double>(c[0], c[1], c[2], c[3]).normalized();
}

struct Blended {
  std::vector<double> pos, quat, Jd, Jp;
};
Blended run_blend(const Setup& u, SkinMethod m, int threads, bool jacobians) {
  Blended b;
  b.pos.assign(static_cast<std::size_t>(u.Q * u.s.P * 3), 0);
  b.quat.assign(static_cast<std::size_t>(u.Q * u.s.P * 4), 0);
  smg::SkinBlendOutputs<double> out;
  out.positions = {b.pos.data(), u.Q, u.s.P};
  out.quaternions = {b.quat.data(), u.Q, u.s.P};
  if (jacobians) {
    b.Jd.assign(static_cast<std::size_t>(u.Q * u.s.P * u.D * 78), -7);
    b.Jp.assign(static_cast<std::size_t>(u.Q * u.s.P * 36), -7);
    out.J_drivers = {b.Jd.data(), u.Q, u.s.P, u.D * 78};
    out.J_point = {b.Jp.data(), u.Q, u.s.P, 36};
  }
  REQUIRE(smg::validate_skin_blend(u.nodes(), u.points(), u.query(), out).is_ok());
  smg::SkinOptions opt;
  opt.method = m;
  smg::skin_blend(u.nodes(), u.points(), u.query(), out, opt, smg::ParallelOptions{threads, 0});
  return b;
}
// Every output bit-identical.
void check_identical(const Blended& a, const Blended& b) {
  CHECK(a.pos == b.pos);
  CHECK(a.quat == b.quat);
  CHECK(a.Jd == b.Jd);
  CHECK(a.Jp == b.Jp);
}

// Output gradients and the gradient buffers of skin_blend_backward.
struct Grads {
  std::vector<double> gpos, grot, gquat;              // dL/d outputs
  std::vector<double> nx, nr, px, pr, pq, w;          // accumulated gradients
};
Grads random_output_grads(smg::test::Rng& rng, const Setup& u) {
  Grads g;
  for (Index i = 0; i < u.Q * u.s.P * 3; ++i) g.gpos.push_back(rng.normal());
  for (Index i = 0; i < u.Q * u.s.P * 3; ++i) g.grot.push_back(rng.normal());
  for (Index i = 0; i < u.Q * u.s.P * 4; ++i) g.gquat.push_back(rng.normal());
  return g;
}
// Every accumulated gradient bit-identical.
void check_identical(const Grads& a, const Grads& b) {
  using Buffer = std::vector<double> Grads::*;
  const std::pair<const char*, Buffer> buffers[] = {{"nx", &Grads::nx}, {"nr", &Grads::nr}, {"px", &Grads::px},
                                                    {"pr", &Grads::pr}, {"pq", &Grads::pq}, {"w", &Grads::w}};
  for (const auto& buffer : buffers) {
    const char* name = buffer.first;
    CAPTURE(name);
    CHECK(a.*buffer.second == b.*buffer.second);
  }
}
void run_backward(const Setup& u, SkinMethod m, int threads, Grads& g,
                  smg::SkinWorkspace<double>& ws) {
  const Index T = u.s.T, N = u.s.N, P = u.s.P;
  g.nx.assign(static_cast<std::size_t>(T * N * 3), 0.5);  // nonzero: backward accumulates
  g.nr.assign(static_cast<std::size_t>(T * N * 3), 0.25);
  g.px.assign(static_cast<std::size_t>(P * 3), 0);
  g.pr.assign(static_cast<std::size_t>(P * 3), 0);
  g.pq.assign(static_cast<std::size_t>(P * 4), 0);
  g.w.assign(static_cast<std::size_t>(P * u.D), 0);
  smg::SkinBlendOutputGradients<double> go;
  go.positions = {g.gpos.data(), u.Q, P};
  go.rotations = {g.grot.data(), u.Q, P};
  go.quaternions = {g.gquat.data(), u.Q, P};
  smg::SkinBlendGradients<double> gr;
  gr.node_positions = {g.nx.data(), T, N};
  gr.node_rotations = {g.nr.data(), T, N};
  gr.points = {g.px.data(), P};
  gr.point_rotations = {g.pr.data(), P};
  gr.point_quaternions = {g.pq.data(), P};
  gr.weights = {g.w.data(), P, u.D};
  REQUIRE(smg::validate_skin_blend_backward(u.nodes(), u.points(), u.query(), go, gr).is_ok());
  smg::SkinOptions opt;
  opt.method = m;
  smg::skin_blend_backward(u.nodes(), u.points(), u.query(), go, gr, ws, opt, smg::ParallelOptions{threads, 0});
}

}  // namespace

TEST_CASE("skin_drivers: the anchor, then its valid neighbours, then -1 padding") {
  SMG_TEST_RNG(rng, 521);
  const Setup u = make_setup(rng, 2, 12, 4, 40, 1);
  for (Index p = 0; p < u.s.P; ++p) {
    const std::int32_t a = u.s.anchor[p];
    CHECK(u.drivers[p * u.D] == a);
    for (Index k = 0; k < u.s.K; ++k)
      CHECK(u.drivers[p * u.D + 1 + k] == u.s.graph_idx[a * u.s.K + k]);
  }
  std::vector<std::int32_t> out(static_cast<std::size_t>(u.s.P * u.D));
  CHECK(smg::validate_skin_drivers(u.graph(), {u.s.anchor.data(), u.s.P}, u.s.N,
                                   {out.data(), u.s.P, u.D})
            .is_ok());
  std::vector<std::int32_t> bad = u.s.anchor;
  bad[3] = int(u.s.N);
  CHECK(smg::validate_skin_drivers(u.graph(), {bad.data(), u.s.P}, u.s.N, {out.data(), u.s.P, u.D})
            .message() == "anchor: element [3] = 12 is out of range [0, N=12)");
  CHECK(smg::validate_skin_drivers(u.graph(), {u.s.anchor.data(), u.s.P}, u.s.N,
                                   {out.data(), u.s.P, u.D - 1})
            .message() == "drivers: expected shape [40][5], got [40][4]");
}

TEST_CASE("skinning_weights batch equals the per-point weights; fallbacks are counted") {
  SMG_TEST_RNG(rng, 522);
  Setup u = make_setup(rng, 3, 10, 4, 50, 1);
  for (Index p = 0; p < u.s.P; ++p) {
    const auto d = gather(u, p, 0);
    std::vector<Vector3<double>> x;
    std::vector<double> sg;
    for (Index k = 0; k < Index(d.size()); ++k) {
      x.push_back(d[k].x_ref);
      sg.push_back(u.s.sigma[u.drivers[p * u.D + k]]);
    }
    std::vector<double> w(d.size());
    smg::skinning_weights_point<double>(Eigen::Map<const Vector3<double>>(&u.s.points[p * 3]),
                                        Index(d.size()), x.data(), sg.data(), w.data());
    for (Index k = 0; k < u.D; ++k)
      CHECK(u.weights[p * u.D + k] == (k < Index(d.size()) ? w[k] : 0.0));
  }
  // Tiny sigmas on every node: every point falls back to its anchor.
  for (auto& s : u.s.sigma) s = 1e-300;
  std::vector<double> w(static_cast<std::size_t>(u.s.P * u.D));
  const Index fallbacks = smg::skinning_weights<double>(
      {u.s.positions.data(), u.s.T, u.s.N}, {u.drivers.data(), u.s.P, u.D}, {u.s.t_ref.data(), u.s.P},
      {u.s.points.data(), u.s.P}, {u.s.sigma.data(), u.s.N}, {w.data(), u.s.P, u.D});
  CHECK(fallbacks == u.s.P);
  for (Index p = 0; p < u.s.P; ++p) CHECK(w[p * u.D] == 1.0);
}

TEST_CASE("skin_blend equals skin_point on every (query, point), values and Jacobians") {
  SMG_TEST_RNG(rng, 523);
  for (bool with_quats : {true, false}) {
    Setup u = make_setup(rng, 4, 12, 5, 30, 3);
    u.with_point_quats = with_quats;
    for (SkinMethod m : kMethods) {
      const std::string method_name = smg::to_string(m);
      CAPTURE(method_name);
      const Blended b = run_blend(u, m, 2, true);
      for (Index q = 0; q < u.Q; ++q)
        for (Index p = 0; p < u.s.P; ++p) {
          const auto d = gather(u, p, u.t_query[q]);
          const Index D = Index(d.size());
          Vector3<double> po;
          Quaternion<double> qo;
          smg::SkinDriverJacobian<double> J[6];
          smg::SkinPointJacobian<double> Jp;
          smg::skin_point(m, d.data(), D, Eigen::Map<const Vector3<double>>(&u.s.points[p * 3]),
                          point_quat(u, p), &po, &qo, J, &Jp);
          const Index qp = q * u.s.P + p;
          CHECK((Eigen::Map<const Vector3<double>>(&b.pos[qp * 3]) - po).norm() < 1e-14 * (1 + po.norm()));
          CHECK((Eigen::Map<const smg::Vector4<double>>(&b.quat[qp * 4]) - smg::to_wxyz(qo)).norm() < 1e-15);
          for (Index k = 0; k < u.D; ++k) {
            const Eigen::Map<const smg::SkinDriverJacobian<double>> Jb(&b.Jd[(qp * u.D + k) * 78]);
            if (k < D)
              CHECK(relative_error(Jb, J[k]) < 1e-14);
            else
              CHECK(Jb.isZero(0));
          }
          CHECK(relative_error(Eigen::Map<const smg::SkinPointJacobian<double>>(&b.Jp[qp * 36]), Jp) < 1e-14);
        }
    }
  }
}

TEST_CASE("skin_blend_backward equals a dense serial accumulation of per-point VJPs") {
  SMG_TEST_RNG(rng, 524);
  Setup u = make_setup(rng, 3, 9, 4, 40, 4);
  u.t_query = {0, 2, 0, 1};  // repeated frames, and frames that are some points' t_ref
  const Index T = u.s.T, N = u.s.N, P = u.s.P;
  for (SkinMethod m : kMethods) {
    const std::string method_name = smg::to_string(m);
    CAPTURE(method_name);
    Grads g = random_output_grads(rng, u);
    smg::SkinWorkspace<double> ws;
    run_backward(u, m, 3, g, ws);
    // Reference: serial loops over (q, p, k) with skin_point_vjp.
    std::vector<double> nx(T * N * 3, 0.5), nr(T * N * 3, 0.25), px(P * 3, 0), pr(P * 3, 0),
        pq(P * 4, 0), w(P * u.D, 0);
    for (Index q = 0; q < u.Q; ++q)
      for (Index p = 0; p < P; ++p) {
        const Index t = u.t_query[q], tr = u.s.t_ref[p];
        const auto d = gather(u, p, t);
        const Index qp = q * P + p;
        const Quaternion<double> qpt = point_quat(u, p);
        Quaternion<double> qo;
        smg::skin_point(m, d.data(), Index(d.size()), Eigen::Map<const Vector3<double>>(&u.s.points[p * 3]),
                        qpt, nullptr, &qo);
        // raw dL/dq' -> right tangent: J_qtᵀ g with the core's quat_tangent_jacobian.
        const Vector3<double> grot = Eigen::Map<const Vector3<double>>(&g.grot[qp * 3]) +
                                     smg::quat_tangent_jacobian(qo).transpose() *
                                         Eigen::Map<const smg::Vector4<double>>(&g.gquat[qp * 4]);
        std::vector<smg::SkinDriverGradient<double>> G(d.size());
        Vector3<double> gp, gphi;
        smg::skin_point_vjp(m, d.data(), Index(d.size()), Eigen::Map<const Vector3<double>>(&u.s.points[p * 3]),
                            qpt, Eigen::Map<const Vector3<double>>(&g.gpos[qp * 3]), grot, G.data(), &gp, &gphi);
        for (Index k = 0; k < Index(d.size()); ++k) {
          const Index n = u.drivers[p * u.D + k];
          for (int c = 0; c < 3; ++c) {
            nx[(t * N + n) * 3 + c] += G[k].x_t(c);
            nx[(tr * N + n) * 3 + c] += G[k].x_ref(c);
            nr[(t * N + n) * 3 + c] += G[k].phi_t(c);
            nr[(tr * N + n) * 3 + c] += G[k].phi_ref(c);
          }
          w[p * u.D + k] += G[k].weight;
        }
        for (int c = 0; c < 3; ++c) {
          px[p * 3 + c] += gp(c);
          pr[p * 3 + c] += gphi(c);
        }
        // raw point quaternion: d q̂ / d q = (I − q̂ q̂ᵀ)/|q| composed with the tangent map.
        const double* c4 = &u.s.point_quats[p * 4];
        const smg::Vector4<double> raw(c4[0], c4[1], c4[2], c4[3]);
        smg::Matrix4<double> Jn;
        smg::normalized(smg::from_wxyz(raw), &Jn);
        // tangent gradient -> gradient w.r.t. the unit 4-vector: 4 J_qt g (J_qtᵀ J_qt = I/4).
        const smg::Vector4<double> g_unit = 4.0 * smg::quat_tangent_jacobian(qpt) * gphi;
        const smg::Vector4<double> g_raw = Jn.transpose() * g_unit;
        for (int c = 0; c < 4; ++c) pq[p * 4 + c] += g_raw(c);
      }
    auto vec = [](const std::vector<double>& v) { return Eigen::Map<const VectorXd>(v.data(), Index(v.size())); };
    CHECK(relative_error(vec(g.nx), vec(nx)) < 1e-14);
    CHECK(relative_error(vec(g.nr), vec(nr)) < 1e-14);
    CHECK(relative_error(vec(g.px), vec(px)) < 1e-14);
    CHECK(relative_error(vec(g.pr), vec(pr)) < 1e-14);
    CHECK(relative_error(vec(g.pq), vec(pq)) < 1e-13);
    CHECK(relative_error(vec(g.w), vec(w)) < 1e-14);
  }
}

TEST_CASE("whole pipeline against central differences: weights from the state, then the blend") {
  // L = Σ a·p' + Σ b·q' (raw 4-vector) with weights = skinning_weights(state). Its gradient is
  // skin_blend_backward (weights as inputs) + skinning_weights_backward(dL/dw).
  SMG_TEST_RNG(rng, 525);
  for (SkinMethod m : kMethods) {
    const std::string method_name = smg::to_string(m);
    CAPTURE(method_name);
    Setup u = make_setup(rng, 2, 5, 3, 6, 2);
    const Index T = u.s.T, N = u.s.N, P = u.s.P;
    Grads g = random_output_grads(rng, u);
    std::fill(g.grot.begin(), g.grot.end(), 0.0);  // the loss is on p' and raw q' only
    auto loss = [&](const Setup& v) {
      Setup w = v;
      w.compute_weights();
      const Blended b = run_blend(w, m, 1, false);
      double L = 0;
      for (std::size_t i = 0; i < b.pos.size(); ++i) L += g.gpos[i] * b.pos[i];
      for (std::size_t i = 0; i < b.quat.size(); ++i) L += g.gquat[i] * b.quat[i];
      return L;
    };
    // Analytic.
    smg::SkinWorkspace<double> ws;
    run_backward(u, m, 2, g, ws);
    for (auto& x : g.nx) x -= 0.5;  // run_backward starts from 0.5 / 0.25
    for (auto& x : g.nr) x -= 0.25;
    std::vector<double> gsig(N, 0.0);
    smg::SkinWeightsGradients<double> wg;
    wg.node_positions = {g.nx.data(), T, N};
    wg.points = {g.px.data(), P};
    wg.sigma = {gsig.data(), N};
    REQUIRE(smg::validate_skinning_weights_backward<double>(
                {u.s.positions.data(), T, N}, {u.drivers.data(), P, u.D}, {u.s.t_ref.data(), P},
                {u.s.points.data(), P}, {u.s.sigma.data(), N}, {g.w.data(), P, u.D}, wg)
                .is_ok());
    smg::skinning_weights_backward<double>({u.s.positions.data(), T, N}, {u.drivers.data(), P, u.D},
                                           {u.s.t_ref.data(), P}, {u.s.points.data(), P},
                                           {u.s.sigma.data(), N}, {g.w.data(), P, u.D}, wg, ws);
    // Central differences over every scalar input (rotations: right tangent of the normalised
    // node quaternion, q ⊗ Exp(h e); point quaternions: raw coefficients).
    const double h = 1e-6;
    auto fd = [&](const std::function<void(Setup&, double)>& perturb) {
      Setup a = u, b = u;
      perturb(a, h);
      perturb(b, -h);
      return (loss(a) - loss(b)) / (2 * h);
    };
    double err = 0, scale = 0;
    auto compare = [&](double analytic, double numeric) {
      err = std::max(err, std::abs(analytic - numeric));
      scale = std::max(scale, std::abs(numeric));
    };
    for (std::size_t i = 0; i < u.s.positions.size(); ++i)
      compare(g.nx[i], fd([&](Setup& s, double e) { s.s.positions[i] += e; }));
    for (Index tn = 0; tn < T * N; ++tn)
      for (int c = 0; c < 3; ++c)
        compare(g.nr[tn * 3 + c], fd([&](Setup& s, double e) {
                  double* q = &s.s.quats[tn * 4];
                  Vector3<double> phi = Vector3<double>::Zero();
                  phi(c) = e;
                  const Quaternion<double> r = Quaternion<double>(q[0], q[1], q[2], q[3]) * smg::so3::exp(phi);
                  q[0] = r.w(); q[1] = r.x(); q[2] = r.y(); q[3] = r.z();
                }));
    for (std::size_t i = 0; i < u.s.points.size(); ++i)
      compare(g.px[i], fd([&](Setup& s, double e) { s.s.points[i] += e; }));
    for (std::size_t i = 0; i < u.s.point_quats.size(); ++i)
      compare(g.pq[i], fd([&](Setup& s, double e) { s.s.point_quats[i] += e; }));
    for (Index n = 0; n < N; ++n)
      compare(gsig[n], fd([&](Setup& s, double e) { s.s.sigma[n] += e; }));
    MESSAGE(std::string(smg::to_string(m)), ": max |analytic - central difference| = ", err, " (largest entry ", scale, ")");
    CHECK(err < 1e-7 * scale);
  }
}

TEST_CASE("results are bit-identical for 1, 2 and 7 threads") {
  SMG_TEST_RNG(rng, 526);
  Setup u = make_setup(rng, 4, 60, 6, 3000, 2);
  for (SkinMethod m : kMethods) {
    const std::string method_name = smg::to_string(m);
    CAPTURE(method_name);
    const Blended b1 = run_blend(u, m, 1, true);
    Grads g1 = random_output_grads(rng, u);
    Grads g2 = g1, g7 = g1;
    smg::SkinWorkspace<double> ws;
    run_backward(u, m, 1, g1, ws);
    for (int threads : {2, 7}) {
      CAPTURE(threads);
      const Blended b = run_blend(u, m, threads, true);
      check_identical(b, b1);
      Grads& g = threads == 2 ? g2 : g7;
      run_backward(u, m, threads, g, ws);  // the same workspace, reused
      check_identical(g, g1);
    }
  }
  // Weights and their backward.
  const Index T = u.s.T, N = u.s.N, P = u.s.P;
  std::vector<double> gw(P * u.D);
  for (auto& x : gw) x = rng.normal();
  std::vector<double> ref_nx, ref_px, ref_sg;
  for (int threads : {1, 2, 7}) {
    smg::ParallelOptions opt;
    opt.threads = threads;
    std::vector<double> w(P * u.D);
    smg::skinning_weights<double>({u.s.positions.data(), T, N}, {u.drivers.data(), P, u.D},
                                  {u.s.t_ref.data(), P}, {u.s.points.data(), P},
                                  {u.s.sigma.data(), N}, {w.data(), P, u.D}, opt);
    CHECK(w == u.weights);
    std::vector<double> nx(T * N * 3, 0), px(P * 3, 0), sg(N, 0);
    smg::SkinWeightsGradients<double> wg;
    wg.node_positions = {nx.data(), T, N};
    wg.points = {px.data(), P};
    wg.sigma = {sg.data(), N};
    smg::SkinWorkspace<double> ws;
    smg::skinning_weights_backward<double>({u.s.positions.data(), T, N}, {u.drivers.data(), P, u.D},
                                           {u.s.t_ref.data(), P}, {u.s.points.data(), P},
                                           {u.s.sigma.data(), N}, {gw.data(), P, u.D}, wg, ws, opt);
    if (threads == 1) {
      ref_nx = nx;
      ref_px = px;
      ref_sg = sg;
    } else {
      CHECK(nx == ref_nx);
      CHECK(px == ref_px);
      CHECK(sg == ref_sg);
    }
  }
}

TEST_CASE("a point set whose nodes all move rigidly together moves rigidly") {
  SMG_TEST_RNG(rng, 527);
  Setup u = make_setup(rng, 3, 15, 5, 200, 2);
  // Frame t = G · frame t_ref for every node, with every point's t_ref = 0.
  const Quaternion<double> g = rng.rotation_with_angle(2.5);
  const Vector3<double> tr = rng.vec3(4);
  std::fill(u.s.t_ref.begin(), u.s.t_ref.end(), 0);
  u.t_query = {1, 2};
  for (Index t = 1; t < 3; ++t) {
    const Quaternion<double> gt = t == 1 ? g : Quaternion<double>(g * g);
    const Vector3<double> ut = t == 1 ? tr : Vector3<double>(g * tr + tr);
    for (Index n = 0; n < u.s.N; ++n) {
      const Vector3<double> x = Eigen::Map<const Vector3<double>>(&u.s.positions[n * 3]);
      const double* c = &u.s.quats[n * 4];
      const Quaternion<double> q = gt * Quaternion<double>(c[0], c[1], c[2], c[3]);
      Eigen::Map<Vector3<double>>(&u.s.positions[(t * u.s.N + n) * 3]) = gt * x + ut;
      double* o = &u.s.quats[(t * u.s.N + n) * 4];
      o[0] = q.w(); o[1] = q.x(); o[2] = q.y(); o[3] = q.z();
    }
  }
  u.compute_weights();
  for (SkinMethod m : kMethods) {
    const std::string method_name = smg::to_string(m);
    CAPTURE(method_name);
    const Blended b = run_blend(u, m, 2, false);
    double worst = 0;
    for (Index q = 0; q < 2; ++q) {
      const Quaternion<double> gt = q == 0 ? g : Quaternion<double>(g * g);
      const Vector3<double> ut = q == 0 ? tr : Vector3<double>(g * tr + tr);
      for (Index p = 0; p < u.s.P; ++p) {
        const Vector3<double> x = Eigen::Map<const Vector3<double>>(&u.s.points[p * 3]);
        const Vector3<double> y = Eigen::Map<const Vector3<double>>(&b.pos[(q * u.s.P + p) * 3]);
        worst = std::max(worst, (y - (gt * x + ut)).norm());
        const Quaternion<double> qo = smg::from_wxyz(&b.quat[(q * u.s.P + p) * 4]);
        CHECK(smg::so3::angular_distance(qo, Quaternion<double>(gt * point_quat(u, p))) < 1e-14);
      }
      // Pairwise distances preserved.
      for (Index p = 1; p < u.s.P; ++p) {
        const Vector3<double> a0 = Eigen::Map<const Vector3<double>>(&u.s.points[(p - 1) * 3]);
        const Vector3<double> b0 = Eigen::Map<const Vector3<double>>(&u.s.points[p * 3]);
        const Vector3<double> a1 = Eigen::Map<const Vector3<double>>(&b.pos[(q * u.s.P + p - 1) * 3]);
        const Vector3<double> b1 = Eigen::Map<const Vector3<double>>(&b.pos[(q * u.s.P + p) * 3]);
        CHECK(std::abs((a1 - b1).norm() - (a0 - b0).norm()) < 1e-13);
      }
    }
    CHECK(worst < 1e-13);
  }
}

TEST_CASE("validation names the argument and the problem") {
  SMG_TEST_RNG(rng, 528);
  Setup u = make_setup(rng, 3, 8, 3, 10, 2);
  smg::SkinBlendOutputs<double> out;
  std::vector<double> pos(u.Q * u.s.P * 3);
  out.positions = {pos.data(), u.Q, u.s.P};
  auto msg = [&](const Setup& v) {
    return smg::validate_skin_blend(v.nodes(), v.points(), v.query(), out).message();
  };
  CHECK(msg(u).empty());
  {
    Setup v = u;
    v.t_query[1] = 3;
    CHECK(msg(v) == "t_query: element [1] = 3 is out of range [0, T=3)");
  }
  {
    Setup v = u;
    v.s.t_ref[4] = -1;
    CHECK(msg(v) == "t_ref: element [4] = -1 is out of range [0, T=3)");
  }
  {
    Setup v = u;
    v.drivers[2 * v.D] = 8;
    CHECK(msg(v) == "drivers: entry [p=2][k=0] = 8 is out of range [-1, N=8)");
  }
  {
    Setup v = u;
    v.drivers[2 * v.D] = -1;
    CHECK(msg(v) == "drivers: entry [p=2][k=0] is -1: every point needs at least one driver");
  }
  {
    Setup v = u;
    v.weights[5 * v.D + 0] = -0.1;
    CHECK(msg(v) == "weights: entry [p=5][k=0] = -0.1 is negative");
  }
  {
    Setup v = u;
    for (Index k = 0; k < v.D; ++k) v.weights[6 * v.D + k] = 0;
    CHECK(msg(v) == "weights: row [p=6] has no positive weight");
  }
  {
    Setup v = u;
    v.s.positions[7] = std::numeric_limits<double>::quiet_NaN();
    CHECK(msg(v) == "positions: element [t=0][i=2] is NaN");
  }
  {
    Setup v = u;
    std::fill(v.s.quats.begin() + 8, v.s.quats.begin() + 12, 0.0);
    CHECK(msg(v) == "quaternions: element [t=0][i=2] is the zero quaternion");
  }
  {
    Setup v = u;
    std::fill(v.s.point_quats.begin() + 4, v.s.point_quats.begin() + 8, 0.0);
    CHECK(msg(v) == "point_quats: element [1] is the zero quaternion");
  }
  {
    Setup v = u;
    v.s.points[4] = std::numeric_limits<double>::infinity();
    CHECK(msg(v) == "points: element [1][1] is Inf");
  }
  std::vector<double> small(3);
  smg::SkinBlendOutputs<double> bad;
  bad.positions = {small.data(), 1, 1};
  CHECK(smg::validate_skin_blend(u.nodes(), u.points(), u.query(), bad).message() ==
        "out_positions: expected shape [Q=2][P=10][3], got [1][1][3]");
  // Weights: sigma must be positive.
  std::vector<double> sig = u.s.sigma;
  sig[3] = 0;
  std::vector<double> w(u.s.P * u.D);
  CHECK(smg::validate_skinning_weights<double>({u.s.positions.data(), u.s.T, u.s.N},
                                               {u.drivers.data(), u.s.P, u.D}, {u.s.t_ref.data(), u.s.P},
                                               {u.s.points.data(), u.s.P}, {sig.data(), u.s.N},
                                               {w.data(), u.s.P, u.D})
            .message() == "sigma: element [3] = 0 is not positive");
  // Backward: a NaN output gradient.
  std::vector<double> gpos(u.Q * u.s.P * 3, 0.0);
  gpos[5] = std::numeric_limits<double>::quiet_NaN();
  smg::SkinBlendOutputGradients<double> go;
  go.positions = {gpos.data(), u.Q, u.s.P};
  CHECK(smg::validate_skin_blend_backward(u.nodes(), u.points(), u.query(), go,
                                          smg::SkinBlendGradients<double>{})
            .message() == "grad_out_positions: element [q=0][p=1] is NaN");
}
