// smg/skin/weights.hpp — distance-aware skinning weights of many points, and their backward.
//
// For point p with drivers k (skin_drivers) and reference frame t_r = t_ref[p]:
//   w_pk = softmax_k( −‖p − x_{n_k}(t_r)‖² / (2 σ_{n_k}²) )              (S2)-(S4)
// computed per point by skinning_weights_point (smg/skin/weights_point.hpp, which documents
// the underflow-safe softmax and the fallback). sigma is per node [N], in length units.
//
// Gradient policy (docs/design.md: weights computed from the state are constants for the gradient
// unless a function says otherwise): skin_blend_backward treats the weights as inputs and can
// return dL/dw [P][D]; the weights' own dependence on the point positions, the node positions
// at t_ref and sigma is added only if the caller passes that dL/dw to
// skinning_weights_backward. Skipping it is the stop-gradient default.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/validate.hpp"
#include "smg/skin/skin_views.hpp"
#include "smg/skin/weights_element.hpp"
#include "smg/skin/weights_point.hpp"

namespace smg {

namespace detail {
template <class S>
inline Status check_sigma(TableView<const S, 1> sigma, Index N, const std::string& name = "sigma") {
  if (Status s = check_table<S, 1>(sigma, N, 1, name); !s) return s;
  for (Index i = 0; i < N; ++i)
    if (!(sigma(i, 0) > S(0))) {
      std::ostringstream s;
      s << name << ": element [" << i << "] = " << sigma(i, 0) << " is not positive";
      return skin_error(s.str());
    }
  return Status::ok();
}

template <class S>
inline Status check_weight_inputs(PositionsView<const S> positions, SkinDriversView drivers,
                                  SkinIndexView t_ref, TableView<const S, 3> points,
                                  TableView<const S, 1> sigma) {
  const Index T = positions.frames(), N = positions.nodes(), P = drivers.rows();
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (Status s = check_drivers(drivers, P, N, "drivers"); !s) return s;
  if (Status s = check_index_array(t_ref, P, T, "t_ref", "T"); !s) return s;
  if (Status s = check_table<S, 3>(points, P, 3, "points"); !s) return s;
  return check_sigma<S>(sigma, N);
}

}  // namespace detail

// sigma [N]: finite and > 0 (length units).
template <class S>
Status validate_skin_sigma(TableView<const S, 1> sigma, Index nodes,
                           const std::string& name = "sigma") {
  return detail::check_sigma<S>(sigma, nodes, name);
}
template <class View, detail::EnableMutableTable<View, 1> = 0>
Status validate_skin_sigma(const View& sigma, Index nodes, const std::string& name = "sigma") {
  return validate_skin_sigma<typename View::Value>(sigma, nodes, name);
}

// Checks skinning_weights' arguments: positions [T][N][3] finite; drivers [P][D] (entries in
// [−1, N), padding trailing, entry 0 valid); t_ref [P] in [0, T); points [P][3] finite;
// sigma [N] finite and > 0; weights_out [P][D].
template <class S>
Status validate_skinning_weights(detail::NonDeducedT<PositionsView<const S>> positions,
                                 SkinDriversView drivers,
                                 SkinIndexView t_ref,
                                 detail::NonDeducedT<TableView<const S, 3>> points,
                                 detail::NonDeducedT<TableView<const S, 1>> sigma,
                                 TableView<S, Eigen::Dynamic> weights_out) {
  if (Status s = detail::check_weight_inputs<S>(positions, drivers, t_ref, points, sigma); !s)
    return s;
  return detail::check_output_table<S, Eigen::Dynamic>(weights_out, drivers.rows(), drivers.cols(),
                                                       "weights");
}

// weights_out[p][k] = w_pk (S2)-(S4), 0 on padding. Returns the number of points whose weights
// used the fallback (S4) (all of their weight on the anchor). Deterministic, multithreaded.
template <class S>
Index skinning_weights(detail::NonDeducedT<PositionsView<const S>> positions,
                       SkinDriversView drivers,
                       SkinIndexView t_ref, detail::NonDeducedT<TableView<const S, 3>> points,
                       detail::NonDeducedT<TableView<const S, 1>> sigma,
                       TableView<S, Eigen::Dynamic> weights_out,
                       ParallelOptions options = {}) {
  const Index Dmax = drivers.cols();
  return parallel_reduce(
      drivers.rows(), Index(0),
      [&](Index begin, Index end) {
        std::vector<Vector3<S>> x(static_cast<std::size_t>(Dmax));
        std::vector<S> sg(static_cast<std::size_t>(Dmax));
        Index fallbacks = 0;
        for (Index p = begin; p < end; ++p)
          if (detail::skinning_weights_row<S>(positions, drivers, t_ref, points, sigma,
                                              weights_out, p, x.data(), sg.data()))
            ++fallbacks;
        return fallbacks;
      },
      [](Index a, Index b) { return a + b; }, options);
}

// Where skinning_weights_backward adds its gradients (each optional: an empty view, null data,
// is not computed). Node positions receive their gradient at each point's t_ref frame.
template <class S>
struct SkinWeightsGradients {
  PositionsView<S> node_positions;  // [T][N][3], +=
  TableView<S, 3> points;           // [P][3], +=
  TableView<S, 1> sigma;            // [N], +=
};

// Checks skinning_weights_backward's arguments: those of skinning_weights, grad_weights [P][D]
// finite, and each non-empty gradient view's shape.
template <class S>
Status validate_skinning_weights_backward(detail::NonDeducedT<PositionsView<const S>> positions,
                                          SkinDriversView drivers, SkinIndexView t_ref,
                                          detail::NonDeducedT<TableView<const S, 3>> points,
                                          detail::NonDeducedT<TableView<const S, 1>> sigma,
                                          detail::NonDeducedT<TableView<const S, Eigen::Dynamic>> grad_weights,
                                          const SkinWeightsGradients<S>& grads) {
  if (Status s = detail::check_weight_inputs<S>(positions, drivers, t_ref, points, sigma); !s)
    return s;
  if (Status s = detail::check_table<S, Eigen::Dynamic>(grad_weights, drivers.rows(),
                                                        drivers.cols(), "grad_weights");
      !s)
    return s;
  if (grads.node_positions.data())
    if (Status s = validate_output(grads.node_positions, positions.frames(), positions.nodes(),
                                   "grad_node_positions");
        !s)
      return s;
  if (grads.points.data())
    if (Status s = detail::check_output_table<S, 3>(grads.points, drivers.rows(), 3, "grad_points"); !s)
      return s;
  if (grads.sigma.data())
    if (Status s = detail::check_output_table<S, 1>(grads.sigma, positions.nodes(), 1, "grad_sigma"); !s)
      return s;
  return Status::ok();
}

// Backward of skinning_weights: given grad_weights = dL/dw [P][D], adds dL/dp to grads.points,
// dL/dx_n(t_ref[p]) to grads.node_positions and dL/dσ_n to grads.sigma (S19). Scatter-adds into
// node buffers go through the workspace's incidence in the fixed order (node, point, driver):
// bit-identical results for any thread count.
template <class S>
void skinning_weights_backward(detail::NonDeducedT<PositionsView<const S>> positions,
                               SkinDriversView drivers,
                               SkinIndexView t_ref,
                               detail::NonDeducedT<TableView<const S, 3>> points,
                               detail::NonDeducedT<TableView<const S, 1>> sigma,
                               detail::NonDeducedT<TableView<const S, Eigen::Dynamic>> grad_weights,
                               const SkinWeightsGradients<S>& grads, SkinWorkspace<S>& ws,
                               ParallelOptions options = {}) {
  const Index P = drivers.rows(), Dmax = drivers.cols(), N = positions.nodes();
  const bool to_nodes = grads.node_positions.data() || grads.sigma.data();
  constexpr Index kStride = 4;  // per edge: dL/dx (3), dL/dσ (1)
  if (to_nodes) {
    ws.incidence.update(drivers, N);
    ws.edge_buffer.resize(ws.incidence.edges.size() * kStride);
  }
  S* buf = ws.edge_buffer.data();
  const auto& inc = ws.incidence;
  parallel_for(
      P,
      [&](Index begin, Index end) {
        std::vector<Vector3<S>> x(static_cast<std::size_t>(Dmax)), gx(x.size());
        std::vector<S> sg(x.size()), w(x.size()), gsg(x.size());
        for (Index p = begin; p < end; ++p) {
          const Index D = detail::skin_load_weight_inputs(positions, drivers, t_ref, sigma, p,
                                                          x.data(), sg.data());
          const Vector3<S> pp = points.row(p);
          skinning_weights_point<S>(pp, D, x.data(), sg.data(), w.data());
          Vector3<S> gp = Vector3<S>::Zero();
          skinning_weights_point_vjp<S>(pp, D, x.data(), sg.data(), w.data(), grad_weights.ptr(p),
                                        &gp, gx.data(), gsg.data());
          if (grads.points.data()) grads.points.row(p) += gp;
          if (to_nodes)
            for (Index k = 0; k < D; ++k) {
              S* e = buf + inc.slot[static_cast<std::size_t>(p * Dmax + k)] * kStride;
              e[0] = gx[k](0);
              e[1] = gx[k](1);
              e[2] = gx[k](2);
              e[3] = gsg[k];
            }
        }
      },
      options);
  if (!to_nodes) return;
  parallel_for(
      N,
      [&](Index begin, Index end) {
        for (Index n = begin; n < end; ++n) {
          S g_sigma = S(0);
          for (Index i = inc.offsets[n]; i < inc.offsets[n + 1]; ++i) {
            const Index e = inc.edges[static_cast<std::size_t>(i)];
            const S* g = buf + i * kStride;
            if (grads.node_positions.data()) {
              S* out = grads.node_positions.ptr(t_ref(e / Dmax, 0), n);
              out[0] += g[0];
              out[1] += g[1];
              out[2] += g[2];
            }
            g_sigma += g[3];
          }
          if (grads.sigma.data()) grads.sigma(n, 0) += g_sigma;
        }
      },
      options);
}

}  // namespace smg
