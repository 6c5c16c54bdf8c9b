// examples/trainer/stage2.cpp — joint optimisation of Gaussians and nodes (stage2.hpp).
#include "trainer/stage2.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "trainer/adam.hpp"
#include "trainer/random.hpp"
#include "trainer/util.hpp"

namespace trainer {

template <class S>
void photometric_loss(const S* image, const S* depth, const float* rgb, const float* target_depth, int W, int H,
                      double lambda_depth, S* gi, S* gd, double* l1, double* dl1) {
  const std::size_t n = sz(W) * H;
  double sum = 0;
  const S inv = static_cast<S>(1.0 / (3.0 * static_cast<double>(n)));
  for (std::size_t k = 0; k < 3 * n; ++k) {
    const double r = static_cast<double>(image[k]) - static_cast<double>(rgb[k]);
    sum += std::abs(r);
    gi[k] = r > 0 ? inv : (r < 0 ? -inv : S(0));
  }
  *l1 = sum / (3.0 * static_cast<double>(n));
  std::size_t valid = 0;
  for (std::size_t k = 0; k < n; ++k) valid += target_depth[k] > 0 ? 1 : 0;
  double dsum = 0;
  const S dinv = valid > 0 ? static_cast<S>(lambda_depth / static_cast<double>(valid)) : S(0);
  for (std::size_t k = 0; k < n; ++k) {
    if (!(target_depth[k] > 0)) {
      if (gd) gd[k] = S(0);
      continue;
    }
    const double r = static_cast<double>(depth[k]) - static_cast<double>(target_depth[k]);
    dsum += std::abs(r);
    if (gd) gd[k] = r > 0 ? dinv : (r < 0 ? -dinv : S(0));
  }
  *dl1 = valid > 0 ? dsum / static_cast<double>(valid) : 0.0;
}

template void photometric_loss<float>(const float*, const float*, const float*, const float*, int, int, double, float*,
                                      float*, double*, double*);
template void photometric_loss<double>(const double*, const double*, const float*, const float*, int, int, double,
                                       double*, double*, double*, double*);

Stage2Result train_gaussians(const Dataset& d, Nodes& nodes, NodeObjective& objective, GaussianModel<float>& m,
                             const Stage2Options& o, const Progress& progress, smg::ParallelOptions parallel) {
  const auto t0 = std::chrono::steady_clock::now();
  const int T = d.frames(), W = d.width, H = d.height, N = nodes.count;
  const std::size_t plane = sz(W) * H;
  Stage2Result r;

  std::vector<smg::splat::Camera<float>> cams;
  for (const Camera& c : d.cameras) cams.push_back(splat_camera<float>(c));
  NodeState<float> ns;
  ns.assign(nodes);
  ModelRenderer<float> renderer;
  ModelGrads<float> g;
  std::vector<float> image(plane * 3), depth(plane), gimage(plane * 3), gdepth(plane);
  std::vector<double> gx(sz(T) * N * 3), gq(sz(T) * N * 3);

  const int G0 = m.count();
  Adam<float> a_means(sz(G0) * 3, o.lr_means), a_quats(sz(G0) * 4, o.lr_quats),
      a_scales(sz(G0) * 3, o.lr_log_scales), a_opacity(sz(G0), o.lr_opacity), a_colors(sz(G0) * 3, o.lr_colors);
  Adam<double> a_nx(sz(T) * N * 3, o.lr_node_position), a_nq(sz(T) * N * 3, o.lr_node_rotation);
  const bool rotations_free = true;  // node rotations drive the Gaussians in every variant

  Random rng(derive_seed(o.seed, 0x57A6E2));
  std::vector<int> order(sz(T));
  std::size_t cursor = order.size();
  double l1_acc = 0, dl1_acc = 0;
  int acc_n = 0;
  const int tail_from = o.iterations - std::max(1, o.iterations / 10);
  objective.update_confidences(nodes);
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  Stage2Timing& tm = r.timing;
  const auto loop_start = Clock::now();

  for (int it = 0; it < o.iterations; ++it) {
    if (cursor >= order.size()) {  // a new epoch: Fisher-Yates shuffle of the frames
      std::iota(order.begin(), order.end(), 0);
      for (std::size_t k = order.size(); k > 1; --k)
        std::swap(order[k - 1], order[sz(rng.below(static_cast<std::int64_t>(k)))]);
      cursor = 0;
    }
    const int t = order[cursor++];
    ns.assign(nodes);
    renderer.render(m, ns, t, cams[sz(t)], image.data(), nullptr, depth.data(), parallel);
    const auto c_loss = Clock::now();
    double l1 = 0, dl1 = 0;
    photometric_loss<float>(image.data(), depth.data(), d.images[sz(t)].data(), d.priors.depth.data() + sz(t) * plane,
                            W, H, o.lambda_depth, gimage.data(), gdepth.data(), &l1, &dl1);
    if (!std::isfinite(l1) || !std::isfinite(dl1))
      throw std::runtime_error("stage 2 diverged (non-finite loss at iteration " + std::to_string(it) + ")");
    if (it >= tail_from) {
      l1_acc += l1;
      dl1_acc += dl1;
      ++acc_n;
    }
    tm.loss += ms(c_loss, Clock::now());
    g.zero(m.count(), T, N);
    renderer.backward(m, ns, cams[sz(t)], gimage.data(), gdepth.data(), g, parallel);
    const auto c_reg = Clock::now();

    // Nodes: photometric gradient + the stage-1 objective.
    for (std::size_t k = 0; k < gx.size(); ++k) {
      gx[k] = g.node_positions[k];
      gq[k] = g.node_rotations[k];
    }
    if (o.hold_unobserved) {
      // Cleared at every unobserved (frame, node), not only at frame t: a Gaussian is skinned from
      // its reference frame to t (DQB of the poses at t relative to those at t_ref), so one render
      // reaches the poses of the reference frames too.
      for (std::size_t s = 0; s < nodes.visible.size(); ++s) {
        if (nodes.visible[s] != 0) continue;
        for (std::size_t c = 0; c < 3; ++c) gx[s * 3 + c] = gq[s * 3 + c] = 0.0;
      }
    }
    if (o.confidence_every > 0 && it > 0 && it % o.confidence_every == 0) objective.update_confidences(nodes);
    const NodeLossTerms nl = objective.evaluate(nodes, o.node_weight, gx.data(), gq.data());
    const auto c_adam = Clock::now();
    tm.regularisers += ms(c_reg, c_adam);

    const double p = o.iterations > 1 ? static_cast<double>(it) / (o.iterations - 1) : 1.0;
    a_means.set_lr(log_lerp(o.lr_means, o.lr_means_final, p));
    a_nx.set_lr(log_lerp(o.lr_node_position, o.lr_node_position_final, p));
    a_nq.set_lr(log_lerp(o.lr_node_rotation, o.lr_node_rotation_final, p));
    a_means.step(m.table.means.data(), g.table.means.data(), parallel);
    a_quats.step(m.table.quats.data(), g.table.quats.data(), parallel);
    a_scales.step(m.table.log_scales.data(), g.table.log_scales.data(), parallel);
    a_opacity.step(m.table.opacity.data(), g.table.opacity.data(), parallel);
    a_colors.step(m.table.colors.data(), g.table.colors.data(), parallel);
    a_nx.step(nodes.positions.data(), gx.data(), parallel);
    if (rotations_free) a_nq.step_rotations(nodes.rotations.data(), gq.data(), parallel);
    tm.adam += ms(c_adam, Clock::now());

    // Density control.
    const int done = it + 1;
    if (o.prune_every > 0 && done >= o.prune_from && done % o.prune_every == 0 && done < o.iterations - o.prune_tail) {
      std::vector<std::uint8_t> keep;
      const int removed = prune(m, o.prune_opacity, o.prune_scale, &keep);
      if (removed > 0) {
        a_means.compact(keep, 3);
        a_quats.compact(keep, 4);
        a_scales.compact(keep, 3);
        a_opacity.compact(keep, 1);
        a_colors.compact(keep, 3);
      }
      r.pruned += removed;
      ns.assign(nodes);
      update_skinning_weights(m, ns, parallel);
      progress.line("stage2", format("it %5d  pruned %d -> %d Gaussians (%d static, %d dynamic)", done, removed,
                                     m.count(), m.fixed, m.dynamic()));
    }
    if (o.log_every > 0 && (it % o.log_every == 0 || done == o.iterations))
      progress.line("stage2", format("it %5d/%d  frame %2d  L1 %.4f  depth %.4f  nodes %.3e  G %d", done, o.iterations,
                                     t, l1, dl1, nl.total(), m.count()));
  }
  tm.total = ms(loop_start, Clock::now());
  const ModelRenderer<float>::Times& rt = renderer.times();
  tm.skin_forward = 1e3 * rt.skin_forward;
  tm.render_forward = 1e3 * rt.render_forward;
  tm.render_backward = 1e3 * rt.render_backward;
  tm.skin_backward = 1e3 * rt.skin_backward;
  tm.other = tm.total - (tm.skin_forward + tm.render_forward + tm.loss + tm.render_backward + tm.skin_backward +
                         tm.regularisers + tm.adam);
  if (o.iterations > 0)
    for (double* v : {&tm.skin_forward, &tm.render_forward, &tm.loss, &tm.render_backward, &tm.skin_backward,
                      &tm.regularisers, &tm.adam, &tm.other, &tm.total})
      *v /= o.iterations;
  progress.line("stage2", format("ms/iteration: skin fwd %.2f  render fwd %.2f  loss %.2f  render bwd %.2f  skin bwd "
                                 "%.2f  regularisers %.2f  adam %.2f  other %.2f  total %.2f",
                                 tm.skin_forward, tm.render_forward, tm.loss, tm.render_backward, tm.skin_backward,
                                 tm.regularisers, tm.adam, tm.other, tm.total));
  objective.update_confidences(nodes);
  r.nodes_final = objective.evaluate(nodes);
  r.iterations = o.iterations;
  r.last_l1 = acc_n > 0 ? l1_acc / acc_n : 0.0;
  r.last_depth = acc_n > 0 ? dl1_acc / acc_n : 0.0;
  r.gaussians = m.count();
  r.fixed = m.fixed;
  r.seconds = seconds_since(t0);
  return r;
}

}  // namespace trainer
