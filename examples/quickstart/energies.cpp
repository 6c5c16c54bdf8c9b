// Quick start 2: build the semantic motion graph, then confidences, C-ARAP and LRM with their
// gradients, in float (the energies come back in double: Accumulator<float>).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <smg/smg.hpp>

namespace {
void check(const smg::Status& s) {  // stop at the first invalid argument
  if (!s) {
    std::fprintf(stderr, "invalid input: %s\n", s.message().c_str());
    std::exit(1);
  }
}
}  // namespace

int main() {
  // Two parts of 6 nodes over 8 frames: one slides along x, one turns; rotations identity.
  const smg::Index T = 8, N = 12, C = 2, K = 4;
  std::vector<float> x(T * N * 3), q(T * N * 4, 0.f), samples(T * N * C);
  std::vector<std::uint8_t> vis(T * N, 1);
  for (smg::Index t = 0; t < T; ++t)
    for (smg::Index i = 0; i < N; ++i) {
      const bool slides = i < N / 2;
      const float a = 0.8f * float(i % (N / 2)), turn = slides ? 0.f : 0.15f * float(t);
      float* p = &x[(t * N + i) * 3];
      p[0] = std::cos(a + turn) + (slides ? 0.1f * float(t) : 4.f);
      p[1] = std::sin(a + turn);
      p[2] = 0.1f * float(i);
      q[(t * N + i) * 4] = 1.f;
      samples[(t * N + i) * C + 0] = slides ? 1.f : 0.f;  // a semantic feature per part
      samples[(t * N + i) * C + 1] = slides ? 0.f : 1.f;
    }
  const smg::PositionsView<float> positions(x.data(), T, N);
  const smg::QuaternionsView<float> rotations(q.data(), T, N);
  const smg::VisibilityView<std::uint8_t> visibility(vis.data(), T, N);
  const smg::FeatureSamplesView<float> feature_samples(samples.data(), T, N, C);

  // 1. The graph: node descriptors from the feature samples, then the exact trajectory KNN
  //    gated by descriptor similarity (cos >= tau), with normalised topology weights.
  std::vector<float> features(N * C);
  const smg::FeaturesView<float> descriptors(features.data(), N, C);
  const smg::DescriptorOptions descriptor_options;
  check(smg::validate_semantic_descriptors(feature_samples, visibility, descriptor_options, descriptors));
  smg::semantic_descriptors(feature_samples, visibility, descriptor_options, descriptors);

  smg::GraphOptions graph_options;
  graph_options.knn.k = K;
  std::vector<std::int32_t> idx(N * K);
  std::vector<float> w(N * K), dist(N * K);
  const smg::TableView<std::int32_t, Eigen::Dynamic> idx_out(idx.data(), N, K);
  const smg::TableView<float, Eigen::Dynamic> w_out(w.data(), N, K), dist_out(dist.data(), N, K);
  check(smg::validate_semantic_graph(positions, visibility, descriptors, graph_options, idx_out, w_out, dist_out));
  const smg::GraphStats stats =
      smg::build_semantic_graph(positions, visibility, descriptors, graph_options, idx_out, w_out, dist_out);
  const smg::NeighborsView<float> graph(idx.data(), w.data(), N, K);
  std::printf("graph: %ld nodes, %ld edges, %ld removed by the gate\n", long(stats.nodes), long(stats.edges),
              long(stats.gate_removed_edges));

  // 2. Per-frame node confidences [T][N] (constants for the gradient).
  std::vector<float> conf(T * N);
  const smg::FrameScalarsView<float> confidence(conf.data(), T, N);
  const smg::ConfidenceOptions confidence_options;
  check(smg::validate_confidence(positions, visibility, graph, confidence_options, confidence));
  smg::node_confidences(positions, visibility, graph, confidence_options, confidence);
  std::printf("confidence: min %.3f, max %.3f\n", *std::min_element(conf.begin(), conf.end()),
              *std::max_element(conf.begin(), conf.end()));

  // 3. C-ARAP and LRM. Each returns its energy and ADDS its gradient into the buffers you pass:
  //    zero them before each evaluation (or let several energies add into the same buffers).
  //    Rotation gradients: a QuaternionsView [T][N][4] gets the gradient w.r.t. the raw
  //    (w, x, y, z) you passed (what Adam on raw quaternions needs); a TangentsView [T][N][3]
  //    the right-tangent one.
  std::vector<float> gx(T * N * 3), gq(T * N * 4);
  const smg::PositionsView<float> grad_positions(gx.data(), T, N);
  const smg::QuaternionsView<float> grad_quats(gq.data(), T, N);
  const smg::CarapOptions carap_options;  // alpha 0.6, gaps {1, 2, 4}
  const smg::LrmOptions lrm_options;      // Huber delta 0.01
  check(smg::validate_carap(positions, rotations, confidence, graph, carap_options, grad_positions, grad_quats));
  check(smg::validate_lrm(positions, confidence, graph, lrm_options, grad_positions));

  double first_norm = 0;
  for (int step = 0; step < 2; ++step) {
    std::fill(gx.begin(), gx.end(), 0.f);  // the buffers are added to
    std::fill(gq.begin(), gq.end(), 0.f);
    const double e_carap =                  // smg::Accumulator<float> is double
        smg::carap(positions, rotations, confidence, graph, carap_options, grad_positions, grad_quats);
    const double e_lrm = smg::lrm(positions, confidence, graph, lrm_options, grad_positions);
    double norm = 0;
    for (float g : gx) norm += double(g) * g;
    norm = std::sqrt(norm);
    if (step == 0) first_norm = norm;
    std::printf("step %d: C-ARAP %.6g, LRM %.6g, |dE/dx| %.6g\n", step, e_carap, e_lrm, norm);
  }
  // Zeroed each time, the two evaluations give the same gradient (and any thread count gives
  // the same bits).
  double again = 0;
  for (float g : gx) again += double(g) * g;
  const bool ok = stats.edges > 0 && std::sqrt(again) == first_norm && first_norm > 0;
  std::printf("quickstart energies: %s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
