// DQB backward's raw node-quaternion gradient (docs/conventions.md "Rotation gradients")
// against central differences of the blend over the raw node quaternion coordinates, and
// against the converter applied to the right-tangent gradient.
#include <doctest/doctest.h>

#include <cstdint>
#include <vector>

#include "skin/skin_test_support.hpp"

using smg::Index;
using smg::test::relative_error;

TEST_CASE("DQB backward: raw node-quaternion gradient agrees with central differences") {
  SMG_TEST_RNG(rng, 303);
  const Index T = 3, N = 6, K = 3, P = 5, Q = 2;
  smg::test::SkinScene s = smg::test::random_scene(rng, T, N, K, P);
  const Index D = K + 1;
  std::vector<std::int32_t> drivers(P * D), tq = {0, 2};
  smg::NeighborsView<double> g(s.graph_idx.data(), s.graph_w.data(), N, K);
  smg::skin_drivers(g, {s.anchor.data(), P}, {drivers.data(), P, D});
  std::vector<double> weights(P * D);
  smg::skinning_weights<double>({s.positions.data(), T, N}, {drivers.data(), P, D},
                                {s.t_ref.data(), P}, {s.points.data(), P}, {s.sigma.data(), N},
                                {weights.data(), P, D});
  std::vector<double> gpos(Q * P * 3), gquat(Q * P * 4);
  for (auto& x : gpos) x = rng.normal();
  for (auto& x : gquat) x = rng.normal();
  auto points = [&] {
    smg::SkinPoints<double> p;
    p.drivers = {drivers.data(), P, D};
    p.weights = {weights.data(), P, D};
    p.t_ref = {s.t_ref.data(), P};
    p.positions = {s.points.data(), P};
    p.quaternions = {s.point_quats.data(), P};
    return p;
  };
  auto loss = [&](const std::vector<double>& quats) {
    std::vector<double> pos(Q * P * 3), qo(Q * P * 4);
    smg::SkinBlendOutputs<double> out;
    out.positions = {pos.data(), Q, P};
    out.quaternions = {qo.data(), Q, P};
    smg::skin_blend<double>({{s.positions.data(), T, N}, {quats.data(), T, N}}, points(),
                            {tq.data(), Q}, out);
    double l = 0;
    for (std::size_t k = 0; k < pos.size(); ++k) l += gpos[k] * pos[k];
    for (std::size_t k = 0; k < qo.size(); ++k) l += gquat[k] * qo[k];
    return l;
  };
  std::vector<double> g_raw(T * N * 4, 0.0), g_tan(T * N * 3, 0.0);
  smg::SkinBlendOutputGradients<double> go;
  go.positions = {gpos.data(), Q, P};
  go.quaternions = {gquat.data(), Q, P};
  smg::SkinBlendGradients<double> gr;
  gr.node_quaternions = {g_raw.data(), T, N};
  gr.node_rotations = {g_tan.data(), T, N};
  const smg::SkinNodes<double> nodes{{s.positions.data(), T, N}, {s.quats.data(), T, N}};
  REQUIRE(smg::validate_skin_blend_backward(nodes, points(), {tq.data(), Q}, go, gr));
  smg::SkinWorkspace<double> ws;
  smg::skin_blend_backward(nodes, points(), {tq.data(), Q}, go, gr, ws);
  std::vector<double> fd(T * N * 4);
  for (Index k = 0; k < T * N * 4; ++k) {
    std::vector<double> qp = s.quats, qm = s.quats;
    qp[k] += 1e-6;
    qm[k] -= 1e-6;
    fd[k] = (loss(qp) - loss(qm)) / 2e-6;
  }
  const Eigen::Map<const Eigen::VectorXd> A(g_raw.data(), T * N * 4), B(fd.data(), T * N * 4);
  CHECK(B.norm() > 0);
  CHECK(relative_error(A, B) < 1e-7);
  std::vector<double> converted(T * N * 4, 0.0);
  smg::quaternion_gradient_from_tangent<double>({s.quats.data(), T, N}, {g_tan.data(), T, N},
                                                {converted.data(), T, N});
  CHECK(relative_error(A, Eigen::Map<const Eigen::VectorXd>(converted.data(), T * N * 4)) < 1e-13);
}
