// smg/energy/carap.hpp — confidence-aware as-rigid-as-possible energy (C-ARAP) with its exact
// gradient (docs/design.md "C-ARAP"; paper section 3.2; docs/math/energy.md (E7)-(E10)).
//
//   d_ij^t = (R_i^t)ᵀ (x_j^t − x_i^t)                                                   (E8)
//   w̃_ij^t = w_ij (α + (1 − α) c_{t,j})                                                  (E7)
//   L = Σ_δ γ_δ Σ_{t=0}^{T−1−δ} Σ_i Σ_{j∈N(i)} w̃_ij^t [ λc ‖d_ij^{t+δ} − d_ij^t‖²
//                                                  + λl (‖d_ij^{t+δ}‖ − ‖d_ij^t‖)² ]       (E9)
//
// The weight is taken at the earlier frame t; gaps δ >= T add nothing; the derivative of ‖d‖ at
// d = 0 is taken as 0 (pinned). Confidences c are constants (stop-gradient): compute them with
// node_confidences() and pass them in. Gradients (E10) are w.r.t. every position x_i^t and every
// rotation R_i^t in the right tangent (R <- R Exp(φ)), and are *added* to the caller's buffers,
// so several energies can accumulate into one gradient.
//
// Parallel scheme (docs/math/energy.md "Determinism"): the frames are cut into blocks whose size
// depends only on T; a block owns the gradient rows of its frames and computes every term whose
// earlier frame it holds. Contributions to the up-to-max(δ) frames past its end go to the
// block's own spill buffer, added afterwards in block order. No float atomics, no buffer per
// edge: results are bit-identical for any thread count and the extra memory is
// blocks × max(δ) × N × 6 scalars.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/quaternion.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/carap_term.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/workspace.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// Checks the inputs and outputs of carap(). `confidence` [T][N] may be empty (all 1), and each
// gradient may be empty (not computed). Confidences must lie in [0, 1].
template <class S, class I>
Status validate_carap(detail::NonDeducedT<PositionsView<const S>> positions,
                      detail::NonDeducedT<QuaternionsView<const S>> rotations,
                      detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                      const NeighborsView<S, I>& graph,
                      const CarapOptions& options, PositionsView<S> grad_positions = {},
                      detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (Status s = validate_quaternions<S>(rotations, T, N, QuaternionNorm::normalize_on_entry,
                                         "rotations");
      !s)
    return s;
  if (Status s = validate_optional_confidence<S>(confidence, T, N); !s) return s;
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (Status s = validate_optional_output(grad_positions, T, N, "grad_positions"); !s) return s;
  if (grad_rotations.is_raw())
    if (Status s = validate_output(grad_rotations.raw(), T, N, "grad_rotations"); !s) return s;
  if (Status s = validate_optional_output(grad_rotations.tangent(), T, N, "grad_rotations"); !s)
    return s;
  return Status::ok();
}

// Number of terms of (E9): Σ_δ max(0, T − δ) · Σ_i |N(i)| (every listed gap counts, also one
// with weight 0). Normalization::mean divides by this; 0 terms give energy 0.
template <class S, class I>
inline Index carap_term_count(const NeighborsView<S, I>& graph, Index frames,
                              const GapList& gaps) {
  Index pairs = 0;
  for (const Gap& g : gaps) pairs += std::max<Index>(0, frames - g.delta);
  return pairs * edge_count(graph);
}

namespace detail {

// The loops of the C-ARAP kernel, each over non-overlapping arrays (restrict: with more than
// a few arrays GCC otherwise gives up on run-time alias checks and does not vectorise).
namespace carap_loops {

// e = x_j − x_i and d = Rᵀ e over n frames; xj and xi are [3][n], R is [9][n] (row-major
// 3x3 per frame).
template <class S>
inline void edge_frames(Index n, const S* SMG_RESTRICT R, const S* SMG_RESTRICT xi,
                        const S* SMG_RESTRICT xj, S* SMG_RESTRICT ex, S* SMG_RESTRICT ey,
                        S* SMG_RESTRICT ez, S* SMG_RESTRICT dx, S* SMG_RESTRICT dy,
                        S* SMG_RESTRICT dz) {
  for (Index l = 0; l < n; ++l) {
    const S a = xj[l] - xi[l], b = xj[n + l] - xi[n + l], c = xj[2 * n + l] - xi[2 * n + l];
    ex[l] = a;
    ey[l] = b;
    ez[l] = c;
    const S Rl[9] = {R[0 * n + l], R[1 * n + l], R[2 * n + l], R[3 * n + l], R[4 * n + l],
                     R[5 * n + l], R[6 * n + l], R[7 * n + l], R[8 * n + l]};
    carap_edge_vector(Rl, a, b, c, dx[l], dy[l], dz[l]);
  }
}

// dst[k] += a[k] for three consecutive [n] rows (a [3][n] block into a node's [3][n] block).
template <class S>
inline void add3(Index n, S* SMG_RESTRICT dst, const S* SMG_RESTRICT ax,
                 const S* SMG_RESTRICT ay, const S* SMG_RESTRICT az) {
  for (Index l = 0; l < n; ++l) {
    dst[l] += ax[l];
    dst[n + l] += ay[l];
    dst[2 * n + l] += az[l];
  }
}
template <class S>
inline void add(Index n, S* SMG_RESTRICT dst, const S* SMG_RESTRICT a) {
  for (Index l = 0; l < n; ++l) dst[l] += a[l];
}
template <class S>
inline void sub(Index n, S* SMG_RESTRICT dst, const S* SMG_RESTRICT a) {
  for (Index l = 0; l < n; ++l) dst[l] -= a[l];
}

// ‖e‖, 1/‖e‖ (0 at e = 0: the derivative of ‖d‖ at d = 0 is taken as 0, pinned), and clears
// the energy accumulator.
template <class S>
inline void lengths(Index n, const S* SMG_RESTRICT ex, const S* SMG_RESTRICT ey,
                    const S* SMG_RESTRICT ez, S* SMG_RESTRICT len, S* SMG_RESTRICT inv_len,
                    S* SMG_RESTRICT eacc) {
  using L = Literal<S>;
  for (Index a = 0; a < n; ++a) inv_len[a] = ex[a] * ex[a] + ey[a] * ey[a] + ez[a] * ez[a];
  sqrt_array(inv_len, len, n);
  for (Index a = 0; a < n; ++a) {
    // Divide by a safe value, then select: a division under the condition would not be
    // vectorised (it could trap on 0).
    const S safe = len[a] > S(0) ? len[a] : S(1);
    const S inv = L(1) / safe;
    inv_len[a] = len[a] > S(0) ? inv : S(0);
    eacc[a] = S(0);
  }
}

// Energy of the pairs (a, a + δ) of one gap (E9), added to eacc[a].
template <class S>
inline void pair_energy(Index n, Index d, const S* SMG_RESTRICT mk, const S* SMG_RESTRICT wb,
                        const S* SMG_RESTRICT dx, const S* SMG_RESTRICT dy,
                        const S* SMG_RESTRICT dz, const S* SMG_RESTRICT len, Literal<S> lam_c,
                        Literal<S> lam_l, S* SMG_RESTRICT eacc) {
  for (Index a = 0; a < n; ++a) {
    const S c = mk[a] * wb[a];
    const S ax = dx[a + d] - dx[a], ay = dy[a + d] - dy[a], az = dz[a + d] - dz[a];
    const S dl = len[a + d] - len[a];
    eacc[a] += carap_term_energy(c, ax, ay, az, dl, lam_c, lam_l);
  }
}

// Energy as pair_energy, and P = ∂/∂d^{t+δ} (= −∂/∂d^t) of the vector term, Q the same for
// ‖d‖ of the length term.
template <class S>
inline void pair_gradient(Index n, Index d, const S* SMG_RESTRICT mk, const S* SMG_RESTRICT wb,
                          const S* SMG_RESTRICT dx, const S* SMG_RESTRICT dy,
                          const S* SMG_RESTRICT dz, const S* SMG_RESTRICT len, Literal<S> lam_c,
                          Literal<S> lam_l, S* SMG_RESTRICT eacc, S* SMG_RESTRICT px,
                          S* SMG_RESTRICT py, S* SMG_RESTRICT pz, S* SMG_RESTRICT q) {
  for (Index a = 0; a < n; ++a) {
    const S c = mk[a] * wb[a];
    const S ax = dx[a + d] - dx[a], ay = dy[a + d] - dy[a], az = dz[a + d] - dz[a];
    const S dl = len[a + d] - len[a];
    eacc[a] += carap_term(c, ax, ay, az, dl, lam_c, lam_l, px[a], py[a], pz[a], q[a]);
  }
}

// G[a] = Σ_g (P_g[a − δ_g] − P_g[a]) for one component and up to three gaps in one pass:
// ∂/∂d^s collects +P from the pair (s − δ, s) and −P from the pair (s, s + δ) (E10). Each P_g
// is preceded by max(δ) zeros, so a − δ_g < 0 reads 0.
template <class S>
inline void gather_pairs(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0) {
  for (Index a = 0; a < m; ++a) G[a] = p0[a - d0] - p0[a];
}
template <class S>
inline void gather_pairs(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0,
                         const S* SMG_RESTRICT p1, Index d1) {
  for (Index a = 0; a < m; ++a) G[a] = (p0[a - d0] - p0[a]) + (p1[a - d1] - p1[a]);
}
template <class S>
inline void gather_pairs(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0,
                         const S* SMG_RESTRICT p1, Index d1, const S* SMG_RESTRICT p2, Index d2) {
  for (Index a = 0; a < m; ++a)
    G[a] = (p0[a - d0] - p0[a]) + (p1[a - d1] - p1[a]) + (p2[a - d2] - p2[a]);
}
template <class S>
inline void gather_pairs_add(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0) {
  for (Index a = 0; a < m; ++a) G[a] += p0[a - d0] - p0[a];
}

// One edge over n frames: F = R G + (H/‖e‖) e (world-frame gradient of x_j) overwrites G;
// fi += F and ri += G × d (right-tangent gradient of R_i), both [3][n].
template <class S>
inline void backprop(Index n, const S* SMG_RESTRICT R, S* SMG_RESTRICT gx, S* SMG_RESTRICT gy,
                     S* SMG_RESTRICT gz, const S* SMG_RESTRICT h, const S* SMG_RESTRICT il,
                     const S* SMG_RESTRICT ex, const S* SMG_RESTRICT ey,
                     const S* SMG_RESTRICT ez, const S* SMG_RESTRICT dx,
                     const S* SMG_RESTRICT dy, const S* SMG_RESTRICT dz, S* SMG_RESTRICT fi,
                     S* SMG_RESTRICT ri) {
  for (Index l = 0; l < n; ++l) {
    const S Rl[9] = {R[0 * n + l], R[1 * n + l], R[2 * n + l], R[3 * n + l], R[4 * n + l],
                     R[5 * n + l], R[6 * n + l], R[7 * n + l], R[8 * n + l]};
    S fx, fy, fz, rx, ry, rz;
    carap_edge_backprop(Rl, gx[l], gy[l], gz[l], h[l], il[l], ex[l], ey[l], ez[l], dx[l], dy[l],
                        dz[l], fx, fy, fz, rx, ry, rz);
    ri[l] += rx;
    ri[n + l] += ry;
    ri[2 * n + l] += rz;
    gx[l] = fx;
    gy[l] = fy;
    gz[l] = fz;
    fi[l] += fx;
    fi[n + l] += fy;
    fi[2 * n + l] += fz;
  }
}

}  // namespace carap_loops

// Frames per block of the C-ARAP frame partition: a function of T and the largest gap only
// (determinism). A block recomputes max δ frames past its end, so longer blocks waste less;
// about 6 blocks (8 to 32 frames each) still give the threads of a small machine fair shares.
// Rounded down so that block + max δ is a multiple of 4 (loops over a block's frames then have
// no scalar remainder).
inline Index carap_block_frames(Index frames, Index max_gap) {
  const Index b = std::min<Index>(32, std::max<Index>(8, (frames + 5) / 6));
  return std::max<Index>(4, b - (b + max_gap) % 4);
}

// One C-ARAP evaluation over the blocks of frames.
template <class S, class I>
struct CarapKernel {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  PositionsView<const S> x;
  QuaternionsView<const S> q;
  FrameScalarsView<const S> conf;  // may be empty: c = 1
  NeighborsView<S, I> graph;
  PositionsView<S> gx;  // may be empty
  TangentsView<S> gr;   // may be empty
  L alpha, lambda_c, lambda_l;
  GapList gaps;           // active gaps (1 <= δ < T)
  std::vector<L> gamma;   // their weights times the overall scale
  Index T = 0, N = 0, K = 0, B = 0, blocks = 0, G = 0;
  S* spill = nullptr;  // [blocks][G][N][3] positions, then the same for rotations
  S* scratch = nullptr;
  Index scratch_per_slot = 0;

  bool gradient() const { return gx.data() != nullptr || gr.data() != nullptr; }
  // Frames stored per block: at most B + max δ, padded to a multiple of 4 so that the loops over
  // a block's frames have no scalar remainder (padding frames carry zeros and weight 0).
  static Index padded(Index frames) { return (frames + 3) / 4 * 4; }
  Index span() const { return padded(B + G); }

  // Scratch scalars per slot: 14 flattened [edge][frame] arrays, one mask and four P arrays
  // (with max(δ) leading zeros) per gap, 16 per-node [component][frame] arrays, and the block's
  // frames node-major: positions and confidences [N][4][span], position and rotation gradients
  // [N][3][span] each.
  Index scratch_size() const {
    const Index n_gaps = static_cast<Index>(gaps.size()), M = K * span();
    return 14 * M + n_gaps * (M + 4 * (M + G)) + 16 * span() + 10 * N * span();
  }

  S* spill_x(Index b) const { return spill + b * G * N * 3; }
  S* spill_r(Index b) const { return spill + (blocks + b) * G * N * 3; }

  // Energy of block b (already scaled); gradients added to the owned rows and the spill.
  Acc block(Index b, Index slot) const {
    const Index t0 = b * B, t1 = std::min(T, t0 + B), te = std::min(T, t1 + G);
    const Index nr = te - t0;    // frames of this block incl. the overlap
    const Index ne = padded(nr); // their storage stride (frames nr .. ne − 1 are zero padding)
    const Index nown = t1 - t0;  // frames whose terms this block computes
    const Index M = K * span();  // capacity of the flattened [edge][frame] arrays
    const bool grad = gradient();
    const bool want_x = gx.data() != nullptr, want_r = gr.data() != nullptr;
    // Members copied to locals: loads through `this` inside the loops would block
    // vectorisation (they may alias the scratch arrays).
    const L lam_c = lambda_c, lam_l = lambda_l, alp = alpha;
    S* p = scratch + slot * scratch_per_slot;
    auto take = [&p](Index n) {
      S* r = p;
      p += n;
      return r;
    };
    // Flattened per-node arrays, index a = e * ne + (s − t0) over active edges e; per-node
    // arrays [component][s − t0]; node-major copies of the block's frames.
    S *Ex = take(M), *Ey = take(M), *Ez = take(M), *Dx = take(M), *Dy = take(M), *Dz = take(M);
    S *Len = take(M), *InvLen = take(M), *Wb = take(M), *Eacc = take(M);
    S *Gx = take(M), *Gy = take(M), *Gz = take(M), *H = take(M);
    S* masks = take(static_cast<Index>(gaps.size()) * M);  // γ_δ [s − t0 < n_δ], per gap
    // Per gap: P (3 components) and Q of every pair, each after max(δ) zeros.
    S* pbase = take(static_cast<Index>(gaps.size()) * 4 * (M + G));
    auto P = [&](std::size_t g, int c) { return pbase + (Index(g) * 4 + c) * (M + G) + G; };
    if (grad) std::fill(pbase, pbase + static_cast<Index>(gaps.size()) * 4 * (M + G), S(0));
    S *R = take(9 * span()), *Fi = take(3 * span()), *Ri = take(3 * span());
    take(span());  // keeps scratch_size's count of per-node arrays
    S* Xb = take(4 * N * span());  // per node: x, y, z, c over the block's frames
    S *GBx = take(3 * N * span()), *GBr = take(3 * N * span());
    const Index n3 = 3 * ne;  // stride of one node in GBx, GBr
    const Index n4 = 4 * ne;  // stride of one node in Xb (positions and confidence together)

    // The block's frames node-major (contiguous per neighbour: the strided [T][N][3] layout
    // would cost a cache line per frame and neighbour).
    std::fill(Xb, Xb + N * n4, S(0));
    for (Index l = 0; l < nr; ++l) {
      const S* row = x.ptr(t0 + l, 0);
      for (Index j = 0; j < N; ++j) {
        S* dst = Xb + j * n4 + l;
        dst[0] = row[3 * j];
        dst[ne] = row[3 * j + 1];
        dst[2 * ne] = row[3 * j + 2];
      }
    }
    for (Index l = 0; l < nown; ++l)
      for (Index j = 0; j < N; ++j) Xb[j * n4 + 3 * ne + l] = conf.data() ? conf(t0 + l, j) : S(1);
    if (want_x) std::fill(GBx, GBx + N * n3, S(0));
    if (want_r) std::fill(GBr, GBr + N * n3, S(0));
    for (std::size_t g = 0; g < gaps.size(); ++g) {
      const Index n_d = std::max<Index>(0, std::min(t1, T - gaps[g].delta) - t0);
      S* mk = masks + static_cast<Index>(g) * M;
      for (Index e = 0; e < K; ++e)
        for (Index l = 0; l < ne; ++l) mk[e * ne + l] = l < n_d ? S(gamma[g]) : S(0);
    }

    // Neighbours are random in memory: the next node's data is requested while this node
    // computes (a neighbour's block data would otherwise arrive from L3 one edge at a time).
    auto prefetch_node = [&](Index i) {
      constexpr Index line = 64 / static_cast<Index>(sizeof(S));
      for (Index l = 0; l < nr; ++l) SMG_PREFETCH(q.ptr(t0 + l, i), 0);
      for (Index k = 0; k < K; ++k) {
        const Index j = graph.indices(i, k);
        if (j < 0) break;
        for (Index o = 0; o < n4; o += line) SMG_PREFETCH(Xb + j * n4 + o, 0);
        if (want_x)
          for (Index o = 0; o < n3; o += line) SMG_PREFETCH(GBx + j * n3 + o, 1);
      }
    };
    if (N > 0) prefetch_node(0);

    Acc energy(0);
    std::vector<std::size_t> active(gaps.size());  // gaps with a pair in this block
    std::vector<Index> nbr(static_cast<std::size_t>(K));
    std::vector<S> wgt(static_cast<std::size_t>(K));
    for (Index i = 0; i < N; ++i) {
      if (i + 1 < N) prefetch_node(i + 1);
      // Active edges: positive weight (a zero weight contributes exactly nothing).
      Index m_e = 0;
      for (Index k = 0; k < K; ++k) {
        const Index j = graph.indices(i, k);
        if (j < 0) break;
        const S w = graph.weights(i, k);
        if (!(w > S(0))) continue;
        nbr[m_e] = j;
        wgt[m_e] = w;
        ++m_e;
      }
      if (m_e == 0) continue;
      const Index m = m_e * ne;
      for (Index l = 0; l < ne; ++l) {
        S Rl[9] = {S(0), S(0), S(0), S(0), S(0), S(0), S(0), S(0), S(0)};
        if (l < nr) rotation_from_wxyz(q.ptr(t0 + l, i), Rl);
        for (int c = 0; c < 9; ++c) R[c * ne + l] = Rl[c];
      }
      const S* Xi = Xb + i * n4;
      // e = x_j − x_i and d = Rᵀ e (E8), and the pair weights w̃ at the earlier frame (E7).
      for (Index e = 0; e < m_e; ++e) {
        const Index j = nbr[e], o = e * ne;
        carap_loops::edge_frames(ne, R, Xi, Xb + j * n4, Ex + o, Ey + o, Ez + o, Dx + o, Dy + o,
                                 Dz + o);
        const S w = wgt[e];
        const S* cj = Xb + j * n4 + 3 * ne;
        for (Index l = 0; l < ne; ++l)
          Wb[o + l] = l < nown ? confidence_edge_weight(w, alp, cj[l]) : S(0);
      }
      carap_loops::lengths(m, Ex, Ey, Ez, Len, InvLen, Eacc);

      // Pair terms (E9) and their d-gradients, flattened over [edge][frame]: the mask zeroes
      // pairs whose earlier frame is not this block's or whose later frame is past T − 1, and
      // pairs that would straddle two edges.
      std::size_t n_active = 0;
      for (std::size_t g = 0; g < gaps.size(); ++g) {
        const Index d = gaps[g].delta;
        if (d >= nr) continue;  // no pair of this gap inside the block
        const Index n = m - d;
        const S* mk = masks + static_cast<Index>(g) * M;
        if (!grad) {
          carap_loops::pair_energy(n, d, mk, Wb, Dx, Dy, Dz, Len, lam_c, lam_l, Eacc);
          continue;
        }
        carap_loops::pair_gradient(n, d, mk, Wb, Dx, Dy, Dz, Len, lam_c, lam_l, Eacc, P(g, 0),
                                   P(g, 1), P(g, 2), P(g, 3));
        for (int c = 0; c < 4; ++c) std::fill(P(g, c) + n, P(g, c) + m, S(0));
        active[n_active++] = g;
      }
      if (grad) {
        // ∂/∂d^s = Σ_δ (P_δ(s − δ) − P_δ(s)), one pass per component over up to three gaps.
        S* Gc[4] = {Gx, Gy, Gz, H};
        for (int c = 0; c < 4; ++c) {
          auto d_of = [&](std::size_t k) { return Index(gaps[active[k]].delta); };
          std::size_t k = 0;
          if (n_active == 0) {
            std::fill(Gc[c], Gc[c] + m, S(0));
          } else if (n_active == 1) {
            carap_loops::gather_pairs(m, Gc[c], P(active[0], c), d_of(0));
            k = 1;
          } else if (n_active == 2) {
            carap_loops::gather_pairs(m, Gc[c], P(active[0], c), d_of(0), P(active[1], c),
                                      d_of(1));
            k = 2;
          } else {
            carap_loops::gather_pairs(m, Gc[c], P(active[0], c), d_of(0), P(active[1], c),
                                      d_of(1), P(active[2], c), d_of(2));
            k = 3;
          }
          for (; k < n_active; ++k)
            carap_loops::gather_pairs_add(m, Gc[c], P(active[k], c), d_of(k));
        }
      }
      energy += Acc(sum_array(Eacc, m));
      if (!grad) continue;

      // Back to the variables (E10): F = R G + H e/‖e‖ is the world-frame gradient of x_j
      // (and minus that of x_i); G × d is the right-tangent gradient of R_i.
      for (Index l = 0; l < 3 * ne; ++l) Fi[l] = Ri[l] = S(0);
      for (Index e = 0; e < m_e; ++e) {
        const Index o = e * ne;
        carap_loops::backprop(ne, R, Gx + o, Gy + o, Gz + o, H + o, InvLen + o, Ex + o, Ey + o,
                              Ez + o, Dx + o, Dy + o, Dz + o, Fi, Ri);
        if (want_x) carap_loops::add3(ne, GBx + nbr[e] * n3, Gx + o, Gy + o, Gz + o);
      }
      if (want_x) carap_loops::sub(n3, GBx + i * n3, Fi);
      if (want_r) carap_loops::add(n3, GBr + i * n3, Ri);
    }

    // Owned frames into the caller's rows, the overlap into this block's spill.
    auto flush = [&](const S* GB, PositionsView<S> out, S* spill_b) {
      for (Index l = 0; l < nr; ++l) {
        S* row = l < nown ? out.ptr(t0 + l, 0) : spill_b + (l - nown) * N * 3;
        if (l < nown) {
          for (Index j = 0; j < N; ++j) {
            const S* src = GB + j * n3 + l;
            row[3 * j] += src[0];
            row[3 * j + 1] += src[ne];
            row[3 * j + 2] += src[2 * ne];
          }
        } else {
          for (Index j = 0; j < N; ++j) {
            const S* src = GB + j * n3 + l;
            row[3 * j] = src[0];
            row[3 * j + 1] = src[ne];
            row[3 * j + 2] = src[2 * ne];
          }
        }
      }
    };
    if (want_x) flush(GBx, gx, spill_x(b));
    if (want_r) flush(GBr, gr, spill_r(b));
    return energy;
  }
};

}  // namespace detail

// C-ARAP energy (E9), returned in Accumulator<S> (double for float). When given, adds the
// gradient w.r.t. positions to grad_positions [T][N][3] and w.r.t. rotations to grad_rotations
// (E10): a TangentsView [T][N][3] receives the right-tangent gradient (R <- R Exp(φ)), a
// QuaternionsView [T][N][4] the gradient for the raw (w, x, y, z) coordinates of `rotations`
// (Q5). rotations [T][N][4] are normalised on entry. confidence [T][N] may be empty (all 1).
// Precondition: validate_carap.
template <class S, class I>
Accumulator<S> carap(detail::NonDeducedT<PositionsView<const S>> positions,
                     detail::NonDeducedT<QuaternionsView<const S>> rotations,
                     detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                     const NeighborsView<S, I>& graph,
                     const CarapOptions& options, PositionsView<S> grad_positions = {},
                     detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                     EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  const Index T = positions.frames(), N = positions.nodes();
  // Debug-build checks of the preconditions that would otherwise read or write out of bounds.
  SMG_ASSERT(rotations.frames() == T && rotations.nodes() == N, "carap: rotations shape");
  SMG_ASSERT(confidence.data() == nullptr || (confidence.frames() == T && confidence.nodes() == N),
             "carap: confidence shape");
  SMG_ASSERT(graph.nodes() == N && graph.weights.rows() == N && graph.weights.cols() == graph.k(),
             "carap: graph shape");
  SMG_ASSERT(grad_positions.data() == nullptr ||
                 (grad_positions.frames() == T && grad_positions.nodes() == N),
             "carap: grad_positions shape");
  SMG_ASSERT(grad_rotations.empty() ||
                 (grad_rotations.frames() == T && grad_rotations.nodes() == N),
             "carap: grad_rotations shape");
  detail::CarapKernel<S, I> k;
  k.T = T;
  k.N = N;
  k.K = graph.k();
  for (const Gap& g : options.gaps)
    if (g.delta >= 1 && g.delta < T && g.weight != 0.0) {
      k.gaps.push_back(g);
      k.G = std::max<Index>(k.G, g.delta);
    }
  if (k.gaps.empty() || N == 0 || k.K == 0) return Acc(0);
  double scale = options.weight;
  if (options.normalization == Normalization::mean) {
    const Index terms = carap_term_count(graph, T, options.gaps);
    if (terms == 0) return Acc(0);
    scale /= static_cast<double>(terms);
  }
  for (const Gap& g : k.gaps) k.gamma.push_back(L(g.weight * scale));
  k.x = positions;
  k.q = rotations;
  k.conf = confidence;
  k.graph = graph;
  k.gx = grad_positions;
  k.gr = grad_rotations.tangent();
  k.alpha = L(options.alpha);
  k.lambda_c = L(options.lambda_c);
  k.lambda_l = L(options.lambda_l);
  k.B = detail::carap_block_frames(T, k.G);
  k.blocks = (T + k.B - 1) / k.B;
  const Index requested = parallel.threads > 0 ? parallel.threads : num_threads();
  const Index slots = std::max<Index>(1, std::min<Index>(requested, k.blocks));
  detail::WorkspaceRef<S> ws(workspace);
  if (grad_rotations.is_raw()) {
    // The kernel works in the tangent; the raw gradient is converted from it at the end (Q5).
    S* g = ws->rotation_grad(static_cast<std::size_t>(T * N * 3));
    std::fill(g, g + T * N * 3, S(0));
    k.gr = TangentsView<S>(g, T, N);
  }
  // Aligned slots (EnergyWorkspace::scratch_aligned): bit-identical for any thread count with
  // AVX's 32-byte packets too.
  k.scratch_per_slot = static_cast<Index>(EnergyWorkspace<S>::aligned_slot_size(static_cast<std::size_t>(k.scratch_size())));
  k.scratch = ws->scratch_aligned(static_cast<std::size_t>(slots * k.scratch_per_slot));
  if (k.gradient()) k.spill = ws->spill(static_cast<std::size_t>(2 * k.blocks * k.G * N * 3));

  std::vector<Acc> partial(static_cast<std::size_t>(k.blocks), Acc(0));
  detail::SlotPool pool(slots);
  ParallelOptions po = parallel;
  po.grain = 1;
  parallel_for_chunks(
      k.blocks,
      [&](Index b, Index, Index) {
        const Index slot = pool.acquire();
        struct Release {
          detail::SlotPool& p;
          Index s;
          ~Release() { p.release(s); }
        } release{pool, slot};
        partial[static_cast<std::size_t>(b)] = k.block(b, slot);
      },
      po);
  Acc energy(0);
  for (const Acc& p : partial) energy += p;

  if (k.gradient()) {
    // Spills into the frames past each block, in block order (deterministic).
    parallel_for(
        T,
        [&](Index begin, Index end) {
          for (Index s = begin; s < end; ++s)
            for (Index b = 0; b < k.blocks; ++b) {
              const Index t1 = std::min(T, b * k.B + k.B);
              const Index te = std::min(T, t1 + k.G);
              if (s < t1 || s >= te) continue;
              if (grad_positions.data()) {
                const S* src = k.spill_x(b) + (s - t1) * N * 3;
                S* dst = grad_positions.ptr(s, 0);
                for (Index c = 0; c < 3 * N; ++c) dst[c] += src[c];
              }
              if (k.gr.data()) {
                const S* src = k.spill_r(b) + (s - t1) * N * 3;
                S* dst = k.gr.ptr(s, 0);
                for (Index c = 0; c < 3 * N; ++c) dst[c] += src[c];
              }
            }
        },
        parallel);
  }
  if (grad_rotations.is_raw())
    quaternion_gradient_from_tangent<S>(rotations, k.gr, grad_rotations.raw(), parallel);
  return energy;
}

}  // namespace smg
