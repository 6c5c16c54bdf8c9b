// Entry points take the caller's mutable views as well as const ones, with no template argument
// (issue 15): every input view parameter whose scalar S can be deduced from another parameter
// (the graph, an output view) is non-deduced, and the validators whose only view is the input
// have an overload for mutable views. Each call below would fail to compile ("couldn't deduce
// template parameter 'S'") without that; the results must equal the const-view calls.
#include <doctest/doctest.h>

#include <cstdint>
#include <tuple>
#include <vector>

#include "smg/smg.hpp"
#include "support/operators.hpp"

using smg::Index;

namespace {

// A small deterministic scene: N nodes on a circle, turning and drifting over T frames.
struct MutableScene {
  Index T = 6, N = 10, K = 3, C = 2;
  std::vector<double> x, q, conf, samples, features, gx, gq;
  std::vector<std::uint8_t> vis;
  std::vector<std::int32_t> idx;
  std::vector<double> w;

  MutableScene() {
    x.resize(T * N * 3);
    q.resize(T * N * 4);
    conf.assign(T * N, 0.5);
    vis.assign(T * N, 1);
    samples.resize(T * N * C);
    for (Index t = 0; t < T; ++t)
      for (Index i = 0; i < N; ++i) {
        const double a = 0.6 * i + 0.05 * t * (1 + i % 3);
        double* p = &x[(t * N + i) * 3];
        p[0] = std::cos(a) + 0.01 * t;
        p[1] = std::sin(a);
        p[2] = 0.1 * i - 0.02 * t;
        const smg::Quaternion<double> r = smg::so3::exp(smg::Vector3<double>(0.1 * t, 0.02 * i, 0.03));
        const smg::Vector4<double> wxyz = smg::to_wxyz(r);
        for (int c = 0; c < 4; ++c) q[(t * N + i) * 4 + c] = wxyz[c];
        samples[(t * N + i) * C + 0] = 1.0;
        samples[(t * N + i) * C + 1] = i < N / 2 ? 0.1 : -0.1;
      }
    // A ring graph: i -> i+1, i+2, i+3 with uniform weights.
    for (Index i = 0; i < N; ++i)
      for (Index k = 0; k < K; ++k) {
        idx.push_back(static_cast<std::int32_t>((i + k + 1) % N));
        w.push_back(1.0 / K);
      }
    features.assign(N * C, 0.0);
    gx.assign(T * N * 3, 0.0);
    gq.assign(T * N * 3, 0.0);
  }
  smg::PositionsView<double> positions() { return {x.data(), T, N}; }
  smg::QuaternionsView<double> rotations() { return {q.data(), T, N}; }
  smg::FrameScalarsView<double> confidence() { return {conf.data(), T, N}; }
  smg::VisibilityView<std::uint8_t> visibility() { return {vis.data(), T, N}; }
  smg::NeighborsView<double> graph() const { return {idx.data(), w.data(), N, K}; }
};

}  // namespace

TEST_CASE("core validators accept mutable views without a template argument") {
  MutableScene s;
  CHECK(smg::validate_positions(s.positions(), s.T, s.N));
  CHECK(smg::validate_quaternions(s.rotations(), s.T, s.N));
  CHECK(smg::validate_visibility(s.visibility(), s.T, s.N));
  CHECK(smg::validate_feature_samples(smg::FeatureSamplesView<double>(s.samples.data(), s.T, s.N, s.C),
                                      s.T, s.N));
  CHECK(smg::validate_features(smg::FeaturesView<double>(s.features.data(), s.N, s.C), s.N));
  // The explicit-argument and braced forms keep working.
  CHECK(smg::validate_positions<double>({s.x.data(), s.T, s.N}, s.T, s.N));
  s.x[4] = std::nan("");
  CHECK(smg::validate_positions(s.positions(), s.T, s.N).message() ==
        smg::validate_positions(smg::PositionsView<const double>(s.positions()), s.T, s.N).message());
}

TEST_CASE("graph entry points accept mutable views without a template argument") {
  MutableScene s;
  smg::TrajectoryDistanceOptions dopt;
  CHECK(smg::validate_trajectory_distance(s.positions(), s.visibility(), 0, 1, dopt));
  CHECK(smg::trajectory_distance(s.positions(), s.visibility(), 0, 1) ==
        smg::trajectory_distance<double>(s.positions(), s.visibility(), 0, 1));

  smg::KnnOptions ko;
  ko.k = 3;
  std::vector<std::int32_t> ki(s.N * 3), ki2(s.N * 3);
  std::vector<double> kd(s.N * 3), kd2(s.N * 3);
  smg::TableView<std::int32_t, Eigen::Dynamic> kiv(ki.data(), s.N, 3), ki2v(ki2.data(), s.N, 3);
  smg::TableView<double, Eigen::Dynamic> kdv(kd.data(), s.N, 3), kd2v(kd2.data(), s.N, 3);
  CHECK(smg::validate_trajectory_knn(s.positions(), s.visibility(), ko, kiv, kdv));
  smg::trajectory_knn(s.positions(), s.visibility(), ko, kiv, kdv);
  smg::trajectory_knn_brute_force(s.positions(), s.visibility(), ko, ki2v, kd2v);
  CHECK(ki == ki2);
  CHECK(kd == kd2);

  smg::FeatureSamplesView<double> samples(s.samples.data(), s.T, s.N, s.C);
  smg::FeaturesView<double> feats(s.features.data(), s.N, s.C);
  smg::DescriptorOptions dso;
  CHECK(smg::validate_semantic_descriptors(samples, s.visibility(), dso, feats));
  smg::semantic_descriptors(samples, s.visibility(), dso, feats);

  smg::GraphOptions go;
  go.knn.k = 3;
  std::vector<std::int32_t> gi(s.N * 3), gi2(s.N * 3);
  std::vector<double> gw(s.N * 3), gd(s.N * 3), gw2(s.N * 3), gd2(s.N * 3);
  smg::TableView<std::int32_t, Eigen::Dynamic> giv(gi.data(), s.N, 3), gi2v(gi2.data(), s.N, 3);
  smg::TableView<double, Eigen::Dynamic> gwv(gw.data(), s.N, 3), gdv(gd.data(), s.N, 3);
  smg::TableView<double, Eigen::Dynamic> gw2v(gw2.data(), s.N, 3), gd2v(gd2.data(), s.N, 3);
  CHECK(smg::validate_semantic_graph(s.positions(), s.visibility(), feats, go, giv, gwv, gdv));
  const smg::GraphStats st = smg::build_semantic_graph(s.positions(), s.visibility(), feats, go, giv, gwv, gdv);
  CHECK(st.edges > 0);
  CHECK(smg::validate_gate_and_weight(kiv, kdv, feats, go, gi2v, gw2v, gd2v));
  smg::gate_and_weight(kiv, kdv, feats, go, gi2v, gw2v, gd2v);
  CHECK(gi == gi2);
  CHECK(gw == gw2);

  smg::NodeSelectionOptions no;
  no.unit = 0.5;
  std::vector<std::int32_t> sel(s.N), asg(s.N);
  std::vector<double> err(s.N);
  smg::TableView<std::int32_t, 1> selv(sel.data(), s.N), asgv(asg.data(), s.N);
  smg::TableView<double, 1> errv(err.data(), s.N);
  CHECK(smg::validate_node_selection(s.positions(), s.visibility(), no, selv, asgv, errv));
  CHECK(smg::select_nodes(s.positions(), s.visibility(), no, selv, asgv, errv).selected > 0);
}

TEST_CASE("energy entry points accept mutable views without a template argument") {
  MutableScene s;
  const smg::NeighborsView<double> g = s.graph();
  std::vector<double> u(s.T * s.N * 3);
  smg::PositionsView<double> uv(u.data(), s.T, s.N);
  CHECK(smg::validate_velocities(s.positions(), uv));
  smg::velocities(s.positions(), uv);
  CHECK(u[0] != 0.0);

  // The regularisers themselves run by the operator list (the test below); their residual forms
  // are not on it.
  smg::CarapOptions ca;
  smg::LrmOptions lo;
  Index carap_blocks = 0, lrm_blocks = 0;
  smg::for_each_carap_residual(s.positions(), s.rotations(), s.confidence(), g, ca,
                               [&](const auto&, int) { ++carap_blocks; }, false,
                               smg::ParallelOptions{1, 0});
  smg::for_each_lrm_residual(s.positions(), s.confidence(), g, lo,
                             [&](const auto&, int) { ++lrm_blocks; }, false,
                             smg::ParallelOptions{1, 0});
  CHECK(carap_blocks > 0);
  CHECK(lrm_blocks > 0);
}

// Every operator of the list (tests/support/operators.hpp), whose run and validate call it with
// no template argument: with the caller's mutable views it gives the bits of its const-view call.
TEST_CASE("every operator of the list accepts mutable views without a template argument") {
  MutableScene s;
  const smg::NeighborsView<double> g = s.graph();
  const smg::test::OperatorInputs<double, std::int32_t, true> mut{s.positions(), s.rotations(), s.visibility(),
                                                                  s.confidence(), g};
  const smg::test::OperatorInputs<double> con{s.positions(), s.rotations(), s.visibility(), s.confidence(), g};
  const std::size_t tn = static_cast<std::size_t>(s.T * s.N);
  int operators = 0;
  smg::test::for_each_operator([&](auto op) {
    INFO(op.name);
    ++operators;
    std::vector<double> gx[2], gr[2], c[2];
    double e[2] = {0, 0};
    for (int k = 0; k < 2; ++k) {
      gx[k].assign(3 * tn, 0.0);
      gr[k].assign(3 * tn, 0.0);
      c[k].assign(tn, 0.0);
      const smg::test::OperatorOutputs<double> out{{gx[k].data(), s.T, s.N}, {gr[k].data(), s.T, s.N}, {c[k].data(), s.T, s.N}};
      if (k == 0) {
        CHECK(op.validate(mut, out));
        e[k] = op.run(mut, out);
      } else {
        CHECK(op.validate(con, out));
        e[k] = op.run(con, out);
      }
    }
    CHECK(e[0] == e[1]);
    CHECK(gx[0] == gx[1]);
    CHECK(gr[0] == gr[1]);
    CHECK(c[0] == c[1]);
    // Something was computed: an energy, a gradient or the confidences.
    CHECK((e[0] != 0 || gx[0] != std::vector<double>(3 * tn, 0.0) || c[0] != std::vector<double>(tn, 0.0)));
  });
  CHECK(operators == static_cast<int>(std::tuple_size<smg::test::Operators>::value));
}

TEST_CASE("skinning weights accept mutable views without a template argument") {
  MutableScene s;
  const Index P = 4, D = s.K + 1;
  std::vector<std::int32_t> anchor = {0, 3, 5, 9}, t_ref = {0, 1, 2, 5}, drivers(P * D);
  smg::TableView<std::int32_t, Eigen::Dynamic> dv(drivers.data(), P, D);
  smg::skin_drivers(s.graph(), smg::SkinIndexView(anchor.data(), P), dv);
  std::vector<double> pts(P * 3, 0.25), sigma(s.N, 0.5), wts(P * D), gw(P * D, 1.0);
  smg::TableView<double, 3> pv(pts.data(), P);
  smg::TableView<double, 1> sv(sigma.data(), s.N);
  smg::TableView<double, Eigen::Dynamic> wv(wts.data(), P, D), gwv(gw.data(), P, D);
  CHECK(smg::validate_skin_sigma(sv, s.N));
  CHECK(smg::validate_skinning_weights(s.positions(), dv, smg::SkinIndexView(t_ref.data(), P), pv, sv, wv));
  smg::skinning_weights(s.positions(), dv, smg::SkinIndexView(t_ref.data(), P), pv, sv, wv);
  CHECK(wts[0] > 0);

  std::vector<double> gnx(s.T * s.N * 3, 0.0), gp(P * 3, 0.0), gs(s.N, 0.0);
  smg::SkinWeightsGradients<double> grads{smg::PositionsView<double>(gnx.data(), s.T, s.N),
                                          smg::TableView<double, 3>(gp.data(), P),
                                          smg::TableView<double, 1>(gs.data(), s.N)};
  smg::SkinWorkspace<double> ws;
  CHECK(smg::validate_skinning_weights_backward(s.positions(), dv, smg::SkinIndexView(t_ref.data(), P),
                                                pv, sv, gwv, grads));
  smg::skinning_weights_backward(s.positions(), dv, smg::SkinIndexView(t_ref.data(), P), pv, sv, gwv,
                                 grads, ws);
}
