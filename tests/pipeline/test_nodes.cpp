// Stage-1 pieces on hand-built node sets: NodeObjective's exact gradients (every variant) against
// central finite differences, and init_rotations (weighted Kabsch) on rigid motion and on
// degenerate neighbourhoods.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"
#include "support/finite_diff.hpp"
#include "support/random.hpp"
#include "trainer/nodes.hpp"

namespace {

using trainer::Nodes;

// N nodes over T frames, visible everywhere, positions and rotations zero (for the caller to fill).
Nodes visible_nodes(int N, int T) {
  Nodes n;
  n.frames = T;
  n.count = N;
  n.positions.resize(static_cast<std::size_t>(T) * N * 3);
  n.rotations.assign(static_cast<std::size_t>(T) * N * 4, 0.0);
  n.visible.assign(static_cast<std::size_t>(T) * N, 1);
  return n;
}

// N nodes over T frames: a cloud ~0.3 m wide moving rigidly-ish plus noise, random rotations,
// about a quarter of the samples unobserved, observations off by 0-4 cm (both sides of the data
// term's Huber threshold, never within 2 mm of it).
Nodes random_nodes(smg::test::Rng& rng, int N, int T, double huber) {
  Nodes n;
  n.frames = T;
  n.count = N;
  n.positions.resize(static_cast<std::size_t>(T) * N * 3);
  n.rotations.resize(static_cast<std::size_t>(T) * N * 4);
  n.visible.resize(static_cast<std::size_t>(T) * N);
  n.observed.assign(static_cast<std::size_t>(T) * N * 3, 0.0);
  std::vector<Eigen::Vector3d> base(N);
  for (auto& b : base) b = 0.15 * rng.vec3();
  for (int t = 0; t < T; ++t) {
    const Eigen::Quaterniond Rt = rng.rotation_with_angle(0.1 * t);
    const Eigen::Vector3d ct = 0.03 * t * rng.vec3();
    for (int i = 0; i < N; ++i) {
      const std::size_t s = static_cast<std::size_t>(t) * N + i;
      const Eigen::Vector3d x = Rt * base[i] + ct + 0.01 * rng.vec3();
      for (int c = 0; c < 3; ++c) n.positions[3 * s + c] = x(c);
      smg::to_wxyz(rng.rotation_with_angle(rng.uniform(0.05, 0.6)), n.rotations.data() + 4 * s);
      n.visible[s] = rng.uniform(0, 1) < 0.75 ? 1 : 0;
      double len = rng.uniform(0.0, 2 * huber);
      while (std::abs(len - huber) < 0.1 * huber) len = rng.uniform(0.0, 2 * huber);
      const Eigen::Vector3d y = x + len * rng.unit3();
      if (n.visible[s])
        for (int c = 0; c < 3; ++c) n.observed[3 * s + c] = y(c);
    }
  }
  return n;
}

// K nearest neighbours at frame 0 with random positive weights; node 0 keeps only two
// neighbours and node 1 one (padding at the end of the row).
void knn_graph(Nodes& n, smg::test::Rng& rng, int K) {
  const int N = n.count;
  n.graph.nodes = N;
  n.graph.k = K;
  n.graph.indices.assign(static_cast<std::size_t>(N) * K, -1);
  n.graph.weights.assign(static_cast<std::size_t>(N) * K, 0.0);
  n.graph.distances.assign(static_cast<std::size_t>(N) * K, 0.0);
  const auto x0 = [&](int i) { return Eigen::Map<const Eigen::Vector3d>(n.positions.data() + 3 * i); };
  for (int i = 0; i < N; ++i) {
    std::vector<int> order(N);
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return (x0(a) - x0(i)).norm() < (x0(b) - x0(i)).norm(); });
    const int used = i == 0 ? 2 : (i == 1 ? 1 : K);
    for (int k = 0; k < used; ++k) {
      n.graph.indices[static_cast<std::size_t>(i) * K + k] = order[k + 1];  // order[0] = i
      n.graph.weights[static_cast<std::size_t>(i) * K + k] = rng.uniform(0.5, 1.5);
    }
  }
}

Eigen::VectorXd as_vector(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

TEST_CASE("NodeObjective: exact gradients match finite differences for every variant") {
  const trainer::NodeLossOptions options;
  for (const std::string name : {"full", "no-lrm", "no-carap", "smg-only", "mosca", "base"}) {
    CAPTURE(name);
    trainer::VariantSpec spec;
    REQUIRE(trainer::parse_variant(name, &spec));
    SMG_TEST_RNG(rng, 7201);
    const int N = 12, T = 5;
    Nodes n = random_nodes(rng, N, T, options.data_huber);
    knn_graph(n, rng, 5);
    trainer::NodeObjective obj(spec, options);
    obj.update_confidences(n);
    const std::vector<double> confidences = obj.confidences();
    const bool uses_conf = spec.rigidity == trainer::Rigidity::carap || spec.lrm;
    CHECK(confidences.size() == (uses_conf ? static_cast<std::size_t>(T * N) : 0u));
    if (uses_conf) {
      // Not all equal, or the stop-gradient would be untested.
      const auto mm = std::minmax_element(confidences.begin(), confidences.end());
      CHECK(*mm.second - *mm.first > 1e-3);
    }

    std::vector<double> gp(static_cast<std::size_t>(T) * N * 3, 0.0), gr(gp.size(), 0.0);
    const trainer::NodeLossTerms terms = obj.evaluate(n, 1.0, gp.data(), gr.data());
    CHECK(terms.data > 0);
    CHECK((terms.rigidity() > 0) == (spec.rigidity != trainer::Rigidity::none));
    CHECK((terms.energy.lrm > 0) == spec.lrm);
    // The value does not depend on whether gradients are asked for, and evaluate keeps the
    // confidences (stop-gradient: only update_confidences changes them).
    const trainer::NodeLossTerms plain = obj.evaluate(n);
    CHECK(plain.total() == doctest::Approx(terms.total()).epsilon(1e-14));
    CHECK(obj.confidences() == confidences);

    const auto total = [&] { return obj.evaluate(n).total(); };
    Eigen::VectorXd fd_p(static_cast<Eigen::Index>(gp.size())), fd_r(static_cast<Eigen::Index>(gr.size()));
    for (std::size_t k = 0; k < n.positions.size(); ++k)
      fd_p(static_cast<Eigen::Index>(k)) = smg::test::central_difference(n.positions[k], total);
    for (int s = 0; s < T * N; ++s) {
      const Eigen::Quaterniond q0 = smg::from_wxyz(n.rotations.data() + 4 * s);
      const auto set = [&](const Eigen::Quaterniond& q) { smg::to_wxyz(q, n.rotations.data() + 4 * s); };
      for (int c = 0; c < 3; ++c) fd_r(3 * s + c) = smg::test::central_difference_tangent(q0, c, set, total);
    }
    CHECK(obj.confidences() == confidences);
    const double ep = smg::test::relative_error(as_vector(gp), fd_p);
    CAPTURE(ep);
    CHECK(fd_p.norm() > 1e-4);
    CHECK(ep < 1e-7);
    if (spec.rigidity != trainer::Rigidity::none) {
      const double er = smg::test::relative_error(as_vector(gr), fd_r);
      CAPTURE(er);
      CHECK(fd_r.norm() > 1e-5);
      CHECK(er < 1e-7);
    } else {
      CHECK(fd_r.norm() < 1e-12);
      CHECK(as_vector(gr).norm() == 0.0);
    }

    // evaluate adds scale * gradient and reports the unscaled terms.
    std::vector<double> gp2 = gp, gr2 = gr;
    const trainer::NodeLossTerms scaled = obj.evaluate(n, 2.5, gp2.data(), gr2.data());
    CHECK(scaled.total() == doctest::Approx(terms.total()).epsilon(1e-12));
    CHECK(smg::test::relative_error(as_vector(gp2), 3.5 * as_vector(gp)) < 1e-12);
    if (spec.rigidity != trainer::Rigidity::none)
      CHECK(smg::test::relative_error(as_vector(gr2), 3.5 * as_vector(gr)) < 1e-12);
  }
}

TEST_CASE("NodeObjective: the ladder's terms are consistent across variants") {
  // Same nodes and graph for every variant: rungs that share a term must report the same value;
  // C-ARAP's confidence-weighted edges (alpha < 1) give less energy than plain ARAP.
  const trainer::NodeLossOptions options;
  SMG_TEST_RNG(rng, 7202);
  Nodes n = random_nodes(rng, 12, 5, options.data_huber);
  knn_graph(n, rng, 5);
  const auto terms = [&](const char* name) {
    trainer::VariantSpec spec;
    REQUIRE(trainer::parse_variant(name, &spec));
    trainer::NodeObjective obj(spec, options);
    obj.update_confidences(n);
    return obj.evaluate(n);
  };
  const trainer::NodeLossTerms base = terms("base"), mosca = terms("mosca"), smg_only = terms("smg-only"),
                               no_carap = terms("no-carap"), no_lrm = terms("no-lrm"), full = terms("full");
  for (const trainer::NodeLossTerms* t : {&mosca, &smg_only, &no_carap, &no_lrm, &full}) CHECK(t->data == base.data);
  CHECK(mosca.rigidity() == smg_only.rigidity());  // plain ARAP; the gate only changes the graph built
  CHECK(no_carap.rigidity() == smg_only.rigidity());  // no-carap: plain ARAP even though confidences exist
  CHECK(full.rigidity() == no_lrm.rigidity());  // C-ARAP
  CHECK(full.energy.lrm == no_carap.energy.lrm);  // LRM with the confidence-aware weights in both
  CHECK(base.rigidity() == 0.0);
  CHECK(base.energy.lrm == 0.0);
  CHECK(no_lrm.energy.lrm == 0.0);
  CHECK(smg_only.energy.lrm == 0.0);
  CHECK(full.energy.lrm > 0);
  CHECK(full.rigidity() > 0);
  CHECK(full.rigidity() < mosca.rigidity());
}

TEST_CASE("NodeObjective: scale 0 reports the unscaled terms and adds nothing") {
  // Stage 2 may run with node_weight = 0 (logging only): the terms must still be reported.
  const trainer::NodeLossOptions options;
  SMG_TEST_RNG(rng, 7203);
  Nodes n = random_nodes(rng, 12, 5, options.data_huber);
  knn_graph(n, rng, 5);
  trainer::NodeObjective obj(trainer::variant_spec(trainer::Variant::full), options);
  obj.update_confidences(n);
  const trainer::NodeLossTerms ref = obj.evaluate(n);
  std::vector<double> gp(n.positions.size(), 0.5), gr(n.positions.size(), 0.25);
  const trainer::NodeLossTerms zero = obj.evaluate(n, 0.0, gp.data(), gr.data());
  CHECK(zero.data == doctest::Approx(ref.data).epsilon(1e-14));
  CHECK(zero.rigidity() == doctest::Approx(ref.rigidity()).epsilon(1e-14));
  CHECK(zero.energy.lrm == doctest::Approx(ref.energy.lrm).epsilon(1e-14));
  CHECK(ref.rigidity() > 0);
  for (double g : gp) REQUIRE(g == 0.5);
  for (double g : gr) REQUIRE(g == 0.25);
}

TEST_CASE("NodeObjective: every term of the library's list reaches stage 1 through its weight alone") {
  // No trainer code names accel, angle or relrot: each is off by default and, with its weight set
  // (what a flag row does), on with that weight per node and frame, and its energy is reported
  // under the library's name. A term added to the list is covered by this loop.
  SMG_TEST_RNG(rng, 7204);
  const int T = 5, N = 12;
  const trainer::NodeLossOptions defaults;
  Nodes n = random_nodes(rng, N, T, defaults.data_huber);
  knn_graph(n, rng, 5);
  const trainer::VariantSpec full = trainer::variant_spec(trainer::Variant::full);
  int checked = 0;
  smg::for_each_term(defaults.regularizers, [&](const char* name, bool, const auto& o) {
    if constexpr (trainer::has_weight<std::decay_t<decltype(o)>>::value) {
      if (trainer::variant_term(name)) return;
      CAPTURE(name);
      const auto on_and_weight = [&](const smg::RegularizerOptions& ro) {
        std::pair<bool, double> out{false, 0.0};
        smg::for_each_term(ro, [&](const char* m, bool on, const auto& p) {
          if constexpr (trainer::has_weight<std::decay_t<decltype(p)>>::value)
            if (std::string(m) == name) out = {on, p.weight};
        });
        return out;
      };
      CHECK_FALSE(on_and_weight(trainer::NodeObjective(full, defaults).regularizer_options(T, N)).first);
      trainer::NodeLossOptions options = defaults;
      smg::for_each_term(options.regularizers, [&](const char* m, bool, auto& p) {
        if constexpr (trainer::has_weight<std::decay_t<decltype(p)>>::value)
          if (std::string(m) == name) p.weight = 0.5;
      });
      trainer::NodeObjective obj(full, options);
      const auto [on, weight] = on_and_weight(obj.regularizer_options(T, N));
      CHECK(on);
      CHECK(weight == 0.5 * (1.0 / (static_cast<double>(T) * N)));
      obj.update_confidences(n);
      const trainer::NodeLossTerms terms = obj.evaluate(n);
      double energy = 0;
      smg::RegularizerResult<double>::each_energy(
          [&](const char* m, double e) {
            if (std::string(m) == name) energy = e;
          },
          terms.energy);
      CHECK(energy > 0);
      ++checked;
    }
  });
  CHECK(checked >= 3);  // accel, angle, relrot at least
}

TEST_CASE("init_rotations: recovers a rigid per-frame rotation; identity at frame 0") {
  SMG_TEST_RNG(rng, 7301);
  const int N = 10, T = 4;
  Nodes n = visible_nodes(N, T);
  std::vector<Eigen::Vector3d> x0(N);
  for (auto& x : x0) x = 0.3 * rng.vec3();
  std::vector<Eigen::Quaterniond> Rt(T);
  for (int t = 0; t < T; ++t) {
    Rt[t] = t == 0 ? Eigen::Quaterniond::Identity() : rng.rotation_with_angle(0.4 * t);
    const Eigen::Vector3d c = rng.vec3();
    for (int i = 0; i < N; ++i) {
      const Eigen::Vector3d x = Rt[t] * x0[i] + c;
      for (int k = 0; k < 3; ++k) n.positions[(static_cast<std::size_t>(t) * N + i) * 3 + k] = x(k);
    }
  }
  const auto check_recovered = [&](const char* graph) {
    const std::string graph_name = graph;
    CAPTURE(graph_name);
    trainer::init_rotations(n);
    for (int t = 0; t < T; ++t)
      for (int i = 0; i < N; ++i) {
        CAPTURE(t);
        CAPTURE(i);
        const Eigen::Quaterniond q = smg::from_wxyz(n.rotations.data() + (static_cast<std::size_t>(t) * N + i) * 4);
        CHECK(std::abs(q.norm() - 1.0) < 1e-12);
        CHECK(Rt[t].angularDistance(q) < 1e-9);
      }
  };
  // Full neighbourhoods with random weights, filled by hand.
  const int K = N - 1;
  n.graph.nodes = N;
  n.graph.k = K;
  n.graph.indices.assign(static_cast<std::size_t>(N) * K, -1);
  n.graph.weights.assign(static_cast<std::size_t>(N) * K, 0.0);
  for (int i = 0; i < N; ++i)
    for (int k = 0, j = 0; j < N; ++j) {
      if (j == i) continue;
      n.graph.indices[static_cast<std::size_t>(i) * K + k] = j;
      n.graph.weights[static_cast<std::size_t>(i) * K + k] = rng.uniform(0.1, 2.0);
      ++k;
    }
  check_recovered("hand-filled");
  // The library's geometric KNN graph (build_graph, ungated).
  n.feature_dim = 4;
  n.descriptors.assign(static_cast<std::size_t>(N) * 4, 0.5);
  trainer::NodeOptions options;
  options.k = 4;
  trainer::build_graph(n, options, /*semantic=*/false);
  REQUIRE(n.graph.k == 4);
  REQUIRE(n.graph.indices[0] >= 0);
  check_recovered("build_graph");
}

TEST_CASE("init_rotations: identity for collinear neighbourhoods and for fewer than two neighbours") {
  SMG_TEST_RNG(rng, 7302);
  // Node 0: neighbours 1, 2, 3 on a line through it. Node 1: one neighbour. Node 4: none.
  // Node 5: general position (neighbours 0, 4, 6), so the motion is not a no-op.
  const int N = 7, T = 3, K = 3;
  Nodes n = visible_nodes(N, T);
  const Eigen::Vector3d origin = rng.vec3(), dir = rng.unit3();
  std::vector<Eigen::Vector3d> x0 = {origin, origin + 0.1 * dir, origin - 0.25 * dir, origin + 0.4 * dir,
                                     rng.vec3(), rng.vec3(), rng.vec3()};
  std::vector<Eigen::Quaterniond> Rt(T);
  for (int t = 0; t < T; ++t) {
    Rt[t] = t == 0 ? Eigen::Quaterniond::Identity() : rng.rotation_with_angle(0.5 + 0.3 * t);
    for (int i = 0; i < N; ++i) {
      const Eigen::Vector3d x = Rt[t] * x0[i];
      for (int k = 0; k < 3; ++k) n.positions[(static_cast<std::size_t>(t) * N + i) * 3 + k] = x(k);
    }
  }
  n.graph.nodes = N;
  n.graph.k = K;
  n.graph.indices.assign(static_cast<std::size_t>(N) * K, -1);
  n.graph.weights.assign(static_cast<std::size_t>(N) * K, 0.0);
  const auto set_row = [&](int i, std::vector<int> js) {
    for (std::size_t k = 0; k < js.size(); ++k) {
      n.graph.indices[static_cast<std::size_t>(i) * K + k] = js[k];
      n.graph.weights[static_cast<std::size_t>(i) * K + k] = 1.0;
    }
  };
  set_row(0, {1, 2, 3});
  set_row(1, {0});
  set_row(2, {0, 1});  // also collinear: 0 and 1 lie on the line through 2
  set_row(5, {0, 4, 6});
  set_row(6, {4, 5});
  trainer::init_rotations(n);
  const auto q = [&](int t, int i) {
    return smg::from_wxyz(n.rotations.data() + (static_cast<std::size_t>(t) * N + i) * 4);
  };
  for (int t = 0; t < T; ++t) {
    CAPTURE(t);
    for (int i : {0, 1, 2, 3, 4}) {
      CAPTURE(i);
      CHECK(q(t, i).w() == 1.0);
      CHECK(q(t, i).vec().norm() == 0.0);
    }
    CHECK(Rt[t].angularDistance(q(t, 5)) < 1e-9);
    CHECK(Rt[t].angularDistance(q(t, 6)) < 1e-9);
  }
}
