// Quick start 3: dual-quaternion blending (DQB) of a few points driven by graph nodes.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <smg/smg.hpp>

namespace {
void check(const smg::Status& s) {
  if (!s) {
    std::fprintf(stderr, "invalid input: %s\n", s.message().c_str());
    std::exit(1);
  }
}
}  // namespace

int main() {
  // Three nodes on the x axis. Between frame 0 and frame 1 the whole set turns 90 degrees about
  // z and rises by 1: every node moves rigidly with the same motion, so DQB reproduces it
  // exactly for any point.
  const smg::Index T = 2, N = 3, K = 2;
  const smg::Quaternion<double> turn(Eigen::AngleAxisd(M_PI / 2, smg::Vector3<double>::UnitZ()));
  const smg::Vector3<double> lift(0, 0, 1);
  std::vector<double> x(T * N * 3), q(T * N * 4);
  for (smg::Index i = 0; i < N; ++i) {
    const smg::Vector3<double> p0(double(i), 0, 0), p1 = turn * p0 + lift;
    for (int c = 0; c < 3; ++c) {
      x[(0 * N + i) * 3 + c] = p0[c];
      x[(1 * N + i) * 3 + c] = p1[c];
    }
    const smg::Vector4<double> r0 = smg::to_wxyz(smg::Quaternion<double>::Identity()), r1 = smg::to_wxyz(turn);
    for (int c = 0; c < 4; ++c) {
      q[(0 * N + i) * 4 + c] = r0[c];
      q[(1 * N + i) * 4 + c] = r1[c];
    }
  }
  const smg::PositionsView<double> positions(x.data(), T, N);
  const smg::QuaternionsView<double> rotations(q.data(), T, N);
  // A hand-written graph [N][K]: each node's two neighbours, weights summing to 1.
  std::vector<std::int32_t> idx = {1, 2,  0, 2,  1, 0};
  std::vector<double> w(N * K, 0.5);
  const smg::NeighborsView<double> graph(idx.data(), w.data(), N, K);

  // Points [P][3] at reference frame t_ref, each anchored to a node; its drivers are the anchor
  // and the anchor's neighbours [P][K+1]; weights softmax(-d^2 / 2 sigma^2) over the drivers.
  const smg::Index P = 3, D = K + 1, Q = 1;
  std::vector<double> points = {0.2, 0.1, 0.0,  1.1, -0.3, 0.2,  1.8, 0.4, -0.1};
  std::vector<std::int32_t> anchor = {0, 1, 2}, t_ref = {0, 0, 0}, t_query = {1};
  std::vector<double> sigma(N, 0.5);
  std::vector<std::int32_t> drivers(P * D);
  std::vector<double> weights(P * D);
  const smg::TableView<std::int32_t, Eigen::Dynamic> drivers_out(drivers.data(), P, D);
  const smg::TableView<double, Eigen::Dynamic> weights_out(weights.data(), P, D);
  const smg::SkinIndexView anchor_view(anchor.data(), P), t_ref_view(t_ref.data(), P);
  const smg::SkinIndexView t_query_view(t_query.data(), Q);
  const smg::TableView<double, 3> point_view(points.data(), P);
  const smg::TableView<double, 1> sigma_view(sigma.data(), N);
  check(smg::validate_skin_drivers(graph, anchor_view, N, drivers_out));
  smg::skin_drivers(graph, anchor_view, drivers_out);
  check(smg::validate_skinning_weights(positions, drivers_out, t_ref_view, point_view, sigma_view, weights_out));
  smg::skinning_weights(positions, drivers_out, t_ref_view, point_view, sigma_view, weights_out);

  // Blend from t_ref to each query frame: positions [Q][P][3], rotations [Q][P][4].
  const smg::SkinNodes<double> nodes{positions, rotations};
  smg::SkinPoints<double> skinned;
  skinned.drivers = drivers_out;
  skinned.weights = weights_out;
  skinned.t_ref = t_ref_view;
  skinned.positions = point_view;  // quaternions left empty: identity reference rotations
  std::vector<double> blended(Q * P * 3), blended_q(Q * P * 4);
  smg::SkinBlendOutputs<double> out;
  out.positions = {blended.data(), Q, P};
  out.quaternions = {blended_q.data(), Q, P};
  check(smg::validate_skin_blend(nodes, skinned, t_query_view, out));
  smg::skin_blend(nodes, skinned, t_query_view, out);  // SkinOptions{}: DQB (SkinMethod::lbs: linear)

  double worst = 0;
  for (smg::Index p = 0; p < P; ++p) {
    const smg::Vector3<double> p0(points[p * 3], points[p * 3 + 1], points[p * 3 + 2]);
    const smg::Vector3<double> got(blended[p * 3], blended[p * 3 + 1], blended[p * 3 + 2]);
    worst = std::max(worst, (got - (turn * p0 + lift)).norm());
    std::printf("point %ld: (%.3f, %.3f, %.3f) -> (%.3f, %.3f, %.3f), weights %.3f %.3f %.3f\n", long(p),
                p0.x(), p0.y(), p0.z(), got.x(), got.y(), got.z(), weights[p * D], weights[p * D + 1],
                weights[p * D + 2]);
  }
  std::printf("max error against the rigid motion: %.1e\n", worst);
  const bool ok = worst < 1e-12;
  std::printf("quickstart dqb: %s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
