// smg/skin/skin_views.hpp — the arrays the batched skinning functions read and write, the
// per-call options, the reusable workspace, and the shared validation helpers.
//
// Layouts (row-major over caller memory, as NumPy/PyTorch; docs/interop.md `dqb`):
//   node positions      [T][N][3]   PositionsView           world units
//   node quaternions    [T][N][4]   QuaternionsView         (w, x, y, z), normalised on entry
//   drivers             [P][D]      int32, node ids, −1 padded (valid entries first; entry 0 is
//                                   the anchor when built by skin_drivers)
//   weights             [P][D]      blend weights (0 on padding)
//   t_ref               [P]         int32 frame of each point's reference pose
//   t_query             [Q]         int32 frames to blend to
//   point positions     [P][3], point quaternions [P][4] (w, x, y, z), normalised on entry
//   outputs             [Q][P][3] positions, [Q][P][4] quaternions
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/skin/blend_point.hpp"

namespace smg {

using SkinIndexView = TableView<const std::int32_t, 1>;                 // [P] or [Q]
using SkinDriversView = TableView<const std::int32_t, Eigen::Dynamic>;  // [P][D]

// Node trajectories.
template <class S>
struct SkinNodes {
  PositionsView<const S> positions;      // [T][N][3]
  QuaternionsView<const S> quaternions;  // [T][N][4] (w, x, y, z), normalised on entry
  SMG_HOST_DEVICE Index frames() const { return positions.frames(); }
  SMG_HOST_DEVICE Index nodes() const { return positions.nodes(); }
};

// The skinned points: drivers, weights, reference time and reference pose.
template <class S>
struct SkinPoints {
  SkinDriversView drivers;                  // [P][D]
  TableView<const S, Eigen::Dynamic> weights;  // [P][D], >= 0, positive maximum per point
  SkinIndexView t_ref;                      // [P]
  TableView<const S, 3> positions;          // [P][3] reference positions
  TableView<const S, 4> quaternions;        // [P][4] reference rotations; empty = identity
  SMG_HOST_DEVICE Index count() const { return drivers.rows(); }
  SMG_HOST_DEVICE Index width() const { return drivers.cols(); }
};

// What the blend computes, on the CPU and the GPU alike. The CPU loops take their threads as a
// separate ParallelOptions argument (skin_blend, skin_blend_backward), as the energy operators
// do, so that device code never sees the CPU thread pool's options.
struct SkinOptions {
  SkinMethod method = SkinMethod::dqb;
};

namespace detail {

// Edges (point p, driver column k) grouped by driven node: the backward passes add each
// node's contributions in the fixed order (node, p, k), which makes their scatter-adds
// deterministic for any thread count without atomics. The point pass writes edge e's
// contribution to buffer slot slot[e], so that the node pass reads each node's contributions
// contiguously (a scattered write is much cheaper than a scattered read once the buffer
// outgrows the cache). Rebuilt only when the driver table changes (compared element-wise;
// O(P·D), negligible next to the blend).
struct SkinIncidence {
  Index nodes = -1, rows = -1, cols = -1;
  std::vector<std::int32_t> drivers;  // the table it was built from
  std::vector<Index> offsets;         // [N + 1]
  std::vector<Index> edges;           // p·D + k, ascending within each node
  std::vector<Index> slot;            // [P·D]: position of edge p·D + k in `edges` (−1: padding)

  void update(SkinDriversView d, Index N) {
    const Index n = d.rows() * d.cols();
    if (N == nodes && d.rows() == rows && d.cols() == cols &&
        std::equal(drivers.begin(), drivers.end(), d.data()))
      return;
    nodes = N;
    rows = d.rows();
    cols = d.cols();
    drivers.assign(d.data(), d.data() + n);
    offsets.assign(static_cast<std::size_t>(N + 1), 0);
    for (Index e = 0; e < n; ++e)
      if (drivers[e] >= 0) ++offsets[static_cast<std::size_t>(drivers[e]) + 1];
    for (Index i = 0; i < N; ++i) offsets[i + 1] += offsets[i];
    edges.resize(static_cast<std::size_t>(offsets[N]));
    slot.assign(static_cast<std::size_t>(n), -1);
    std::vector<Index> fill(offsets.begin(), offsets.end() - 1);
    for (Index e = 0; e < n; ++e)
      if (drivers[e] >= 0) {
        slot[e] = fill[drivers[e]]++;
        edges[static_cast<std::size_t>(slot[e])] = e;
      }
  }
};

inline Status skin_error(const std::string& s) { return Status::error(s); }

// A [rows] int32 array whose every value lies in [0, bound).
inline Status check_index_array(SkinIndexView a, Index rows, Index bound, const std::string& name,
                                const char* bound_name) {
  if (a.rows() != rows) {
    std::ostringstream s;
    s << name << ": expected " << rows << " entries, got " << a.rows();
    return skin_error(s.str());
  }
  if (rows > 0 && a.data() == nullptr) return skin_error(name + ": null data pointer");
  for (Index i = 0; i < rows; ++i)
    if (a(i, 0) < 0 || a(i, 0) >= bound) {
      std::ostringstream s;
      s << name << ": element [" << i << "] = " << a(i, 0) << " is out of range [0, " << bound_name
        << "=" << bound << ")";
      return skin_error(s.str());
    }
  return Status::ok();
}

// Finite values in a [rows][cols] table of the given shape (cols < 0: any).
template <class T, int C>
inline Status check_table(TableView<const T, C> a, Index rows, Index cols, const std::string& name) {
  if (a.rows() != rows || (cols >= 0 && a.cols() != cols)) {
    std::ostringstream s;
    s << name << ": expected shape [" << rows << "][" << (cols >= 0 ? std::to_string(cols) : "any")
      << "], got [" << a.rows() << "][" << a.cols() << "]";
    return skin_error(s.str());
  }
  if (a.size() > 0 && a.data() == nullptr) return skin_error(name + ": null data pointer");
  for (Index i = 0; i < a.rows(); ++i)
    for (Index c = 0; c < a.cols(); ++c)
      if (!std::isfinite(a(i, c))) {
        std::ostringstream s;
        s << name << ": element [" << i << "]";
        if (a.cols() > 1) s << "[" << c << "]";
        s << " is " << (std::isnan(a(i, c)) ? "NaN" : "Inf");
        return skin_error(s.str());
      }
  return Status::ok();
}

// Quaternion rows: finite (checked by check_table) and nonzero.
template <class S>
inline Status check_quaternion_rows(TableView<const S, 4> q, const std::string& name) {
  for (Index i = 0; i < q.rows(); ++i)
    if (!(q.row(i).norm() > S(0))) {
      std::ostringstream s;
      s << name << ": element [" << i << "] is the zero quaternion";
      return skin_error(s.str());
    }
  return Status::ok();
}

// Driver table [P][D]: entries in [−1, N), −1 only as trailing padding, entry 0 valid.
inline Status check_drivers(SkinDriversView d, Index points, Index N, const std::string& name) {
  if (d.rows() != points || d.cols() < 1) {
    std::ostringstream s;
    s << name << ": expected shape [P=" << points << "][D>=1], got [" << d.rows() << "]["
      << d.cols() << "]";
    return skin_error(s.str());
  }
  if (d.size() > 0 && d.data() == nullptr) return skin_error(name + ": null data pointer");
  // The message is formatted only on failure: every skinning call validates its P·D entries,
  // and building a stream per entry cost more than the blend itself (a trainer validates every
  // iteration).
  const auto fail = [&](Index p, Index k, const char* what, bool show_value) {
    std::ostringstream s;
    s << name << ": entry [p=" << p << "][k=" << k << "] ";
    if (show_value) s << "= " << d(p, k) << " is out of range [-1, N=" << N << ")";
    s << what;
    return skin_error(s.str());
  };
  for (Index p = 0; p < d.rows(); ++p) {
    bool padding = false;
    for (Index k = 0; k < d.cols(); ++k) {
      const std::int32_t n = d(p, k);
      if (n < -1 || n >= N) return fail(p, k, "", true);
      if (n == -1) {
        if (k == 0) return fail(p, k, "is -1: every point needs at least one driver", false);
        padding = true;
      } else if (padding) {
        return fail(p, k, "is a driver after -1 padding", false);
      }
    }
  }
  return Status::ok();
}

// Weights [P][D]: finite, >= 0, 0 on padding, positive maximum per point.
template <class S>
inline Status check_weights(TableView<const S, Eigen::Dynamic> w, SkinDriversView d,
                            const std::string& name) {
  if (Status s = check_table<S, Eigen::Dynamic>(w, d.rows(), d.cols(), name); !s) return s;
  for (Index p = 0; p < w.rows(); ++p) {
    S mx = S(0);
    for (Index k = 0; k < w.cols(); ++k) {
      const S v = w(p, k);
      if (v < S(0) || (d(p, k) < 0 && v != S(0))) {
        std::ostringstream s;
        s << name << ": entry [p=" << p << "][k=" << k << "] = " << v
          << (v < S(0) ? " is negative" : " is nonzero on a padding (-1) driver");
        return skin_error(s.str());
      }
      mx = std::max(mx, v);
    }
    if (!(mx > S(0))) {
      std::ostringstream s;
      s << name << ": row [p=" << p << "] has no positive weight";
      return skin_error(s.str());
    }
  }
  return Status::ok();
}

// Points: drivers, weights, t_ref, positions, optional quaternions, against T frames, N nodes.
template <class S>
inline Status check_points(const SkinPoints<S>& pts, Index T, Index N, bool with_weights) {
  const Index P = pts.count();
  if (Status s = check_drivers(pts.drivers, P, N, "drivers"); !s) return s;
  if (with_weights)
    if (Status s = check_weights<S>(pts.weights, pts.drivers, "weights"); !s) return s;
  if (Status s = check_index_array(pts.t_ref, P, T, "t_ref", "T"); !s) return s;
  if (Status s = check_table<S, 3>(pts.positions, P, 3, "points"); !s) return s;
  if (pts.quaternions.rows() != 0 || pts.quaternions.data() != nullptr) {  // present
    if (Status s = check_table<S, 4>(pts.quaternions, P, 4, "point_quats"); !s) return s;
    if (Status s = check_quaternion_rows<S>(pts.quaternions, "point_quats"); !s) return s;
  }
  return Status::ok();
}

// A caller-owned output or gradient table: shape and non-null only.
template <class S, int C>
inline Status check_output_table(TableView<S, C> a, Index rows, Index cols, const std::string& name) {
  if (a.rows() != rows || a.cols() != cols) {
    std::ostringstream s;
    s << name << ": expected shape [" << rows << "][" << cols << "], got [" << a.rows() << "]["
      << a.cols() << "]";
    return skin_error(s.str());
  }
  if (a.size() > 0 && a.data() == nullptr) return skin_error(name + ": null data pointer");
  return Status::ok();
}

// Normalised node quaternion (t, n) and position. The loaders below are host-device: the CPU
// loops and the CUDA kernels (smg/cuda/dqb.cuh) read the drivers through them.
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_node_quaternion(QuaternionsView<const S> q, Index t, Index n) {
  using std::sqrt;
  const S* c = q.ptr(t, n);
  const Quaternion<S> r(c[0], c[1], c[2], c[3]);
  return Quaternion<S>(r.coeffs() * (S(1) / sqrt(r.coeffs().squaredNorm())));
}
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_point_quaternion(TableView<const S, 4> q, Index p, S* norm = nullptr) {
  if (q.rows() == 0) {
    if (norm) *norm = S(1);
    return Quaternion<S>::Identity();
  }
  const S* c = q.ptr(p);
  const Quaternion<S> r(c[0], c[1], c[2], c[3]);
  const S n = r.coeffs().norm();
  if (norm) *norm = n;
  return Quaternion<S>(r.coeffs() / n);
}

// Loads the reference half of a point's drivers (positions, normalised quaternions at t_ref,
// weights). Returns the number of valid drivers.
template <class S>
SMG_HOST_DEVICE inline Index skin_load_ref(const SkinNodes<S>& nodes, const SkinPoints<S>& pts, Index p,
                           bool with_weights, SkinDriver<S>* d) {
  const Index tr = pts.t_ref(p, 0);
  Index D = 0;
  for (Index k = 0; k < pts.width(); ++k) {
    const std::int32_t n = pts.drivers(p, k);
    if (n < 0) break;
    d[D].x_ref = nodes.positions(tr, n);
    d[D].q_ref = skin_node_quaternion(nodes.quaternions, tr, n);
    d[D].weight = with_weights ? pts.weights(p, k) : S(0);
    ++D;
  }
  return D;
}
// Loads the query half (poses at frame t) of a point's first D drivers.
template <class S>
SMG_HOST_DEVICE inline void skin_load_query(const SkinNodes<S>& nodes, const SkinPoints<S>& pts, Index p, Index t,
                            Index D, SkinDriver<S>* d) {
  for (Index k = 0; k < D; ++k) {
    const std::int32_t n = pts.drivers(p, k);
    d[k].x_t = nodes.positions(t, n);
    d[k].q_t = skin_node_quaternion(nodes.quaternions, t, n);
  }
}

}  // namespace detail

// A [rows] int32 index array (anchor [P], t_ref [P], t_query [Q]) whose values must lie in
// [0, bound); `name` and `bound_name` appear in the message (e.g. "anchor.npy", "N").
inline Status validate_skin_index_array(SkinIndexView a, Index rows, Index bound,
                                        const std::string& name, const char* bound_name) {
  return detail::check_index_array(a, rows, bound, name, bound_name);
}

// Reusable scratch of the backward passes (skin_blend_backward, skinning_weights_backward):
// the node incidence of the driver table and a per-edge buffer. Keep one per thread of calls
// and reuse it across iterations; it allocates only when the sizes or the driver table change.
// Its contents are internal.
template <class S>
struct SkinWorkspace {
  detail::SkinIncidence incidence;
  std::vector<S> edge_buffer;
};

}  // namespace smg
