// tests/energy/scene.hpp — small owned test scenes for the energy tests and benchmarks: node
// trajectories, rotations, visibility and a K-neighbour graph, with views onto them.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include "smg/core/so3.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/confidence.hpp"
#include "smg/energy/options.hpp"
#include "smg/graph/neighbors.hpp"
#include "support/random.hpp"

namespace smg::test {

template <class S>
struct Scene {
  Index T = 0, N = 0, K = 0;
  std::vector<S> x;             // [T][N][3]
  std::vector<S> q;             // [T][N][4] (w, x, y, z)
  std::vector<std::uint8_t> v;  // [T][N]
  std::vector<S> c;             // [T][N] confidences (filled by the caller when needed)
  std::vector<std::int32_t> idx;  // [N][K]
  std::vector<S> w;               // [N][K]

  // T frames of N nodes: x, q, v and c get their sizes (new entries 0; shrinking T keeps the
  // first frames).
  void resize(Index frames, Index nodes) {
    T = frames;
    N = nodes;
    x.resize(static_cast<std::size_t>(T * N * 3));
    q.resize(static_cast<std::size_t>(T * N * 4));
    v.resize(static_cast<std::size_t>(T * N));
    c.resize(static_cast<std::size_t>(T * N));
  }

  PositionsView<const S> positions() const { return {x.data(), T, N}; }
  QuaternionsView<const S> rotations() const { return {q.data(), T, N}; }
  VisibilityView<const std::uint8_t> visibility() const { return {v.data(), T, N}; }
  FrameScalarsView<const S> confidence() const { return {c.data(), T, N}; }
  NeighborsView<S> graph() const { return {idx.data(), w.data(), N, K}; }

  Vector3<S> pos(Index t, Index i) const { return Eigen::Map<const Vector3<S>>(&x[(t * N + i) * 3]); }
  void set_pos(Index t, Index i, const Vector3<S>& p) {
    Eigen::Map<Vector3<S>> m(&x[(t * N + i) * 3]);
    m = p;
  }
  Quaternion<S> rot(Index t, Index i) const {
    const S* p = &q[(t * N + i) * 4];
    return Quaternion<S>(p[0], p[1], p[2], p[3]);
  }
  void set_rot(Index t, Index i, const Quaternion<S>& r) {
    S* p = &q[(t * N + i) * 4];
    p[0] = r.w();
    p[1] = r.x();
    p[2] = r.y();
    p[3] = r.z();
  }

  // The same scene in scalar U.
  template <class U>
  Scene<U> cast() const {
    auto in_u = [](const std::vector<S>& a) { return std::vector<U>(a.begin(), a.end()); };
    return Scene<U>{T, N, K, in_u(x), in_u(q), v, in_u(c), idx, in_u(w)};
  }
};

// K nearest neighbours of each node by frame-0 distance (brute force; tests and benches only —
// the library's graph builder lives in smg/graph), weights 1/degree, -1 padding.
template <class S>
void knn_graph(Scene<S>& s, Index K) {
  s.K = K;
  s.idx.assign(static_cast<std::size_t>(s.N * K), -1);
  s.w.assign(static_cast<std::size_t>(s.N * K), S(0));
  std::vector<std::pair<double, Index>> d(static_cast<std::size_t>(s.N));
  for (Index i = 0; i < s.N; ++i) {
    Index n = 0;
    for (Index j = 0; j < s.N; ++j) {
      if (j == i) continue;
      d[static_cast<std::size_t>(n++)] = {(s.pos(0, j) - s.pos(0, i)).squaredNorm(), j};
    }
    const Index kk = std::min(K, n);
    std::partial_sort(d.begin(), d.begin() + kk, d.begin() + n);
    for (Index k = 0; k < kk; ++k) {
      s.idx[static_cast<std::size_t>(i * K + k)] = static_cast<std::int32_t>(d[k].second);
      s.w[static_cast<std::size_t>(i * K + k)] = S(1) / S(kk);
    }
  }
}

// Random neighbours (distinct, no self edges), degrees between min_deg and K, random positive
// weights; exercises padding and non-normalised rows.
template <class S>
void random_graph(Scene<S>& s, Index K, Index min_deg, Rng& rng) {
  s.K = K;
  s.idx.assign(static_cast<std::size_t>(s.N * K), -1);
  s.w.assign(static_cast<std::size_t>(s.N * K), S(0));
  std::vector<Index> perm(static_cast<std::size_t>(s.N));
  for (Index i = 0; i < s.N; ++i) {
    std::iota(perm.begin(), perm.end(), Index(0));
    std::shuffle(perm.begin(), perm.end(), rng.engine);
    const Index deg = std::min<Index>(s.N - 1, rng.integer(static_cast<int>(min_deg), static_cast<int>(K)));
    Index k = 0;
    for (Index j : perm) {
      if (k == deg) break;
      if (j == i) continue;
      s.idx[static_cast<std::size_t>(i * K + k)] = static_cast<std::int32_t>(j);
      s.w[static_cast<std::size_t>(i * K + k)] = S(rng.uniform(0.2, 1.0));
      ++k;
    }
  }
}

// Random smooth trajectories: each node starts at a random point and moves along a random
// low-frequency path; rotations drift smoothly; visibility mostly 1; confidences random in
// [0, 1].
inline Scene<double> random_scene(Index T, Index N, Index K, Rng& rng, bool knn = false) {
  Scene<double> s;
  s.resize(T, N);
  for (Index i = 0; i < N; ++i) {
    const Vector3<double> p0 = rng.vec3(1.0), vel = rng.vec3(0.05), acc = rng.vec3(0.01);
    const Quaternion<double> r0 = rng.quaternion();
    const Vector3<double> spin = rng.vec3(0.1);
    for (Index t = 0; t < T; ++t) {
      const double tt = static_cast<double>(t);
      s.set_pos(t, i, p0 + tt * vel + 0.5 * tt * tt * acc + rng.vec3(0.02));
      s.set_rot(t, i, r0 * so3::exp(Vector3<double>(tt * spin + rng.vec3(0.05))));
      s.v[static_cast<std::size_t>(t * N + i)] = rng.uniform(0, 1) < 0.9 ? 1 : 0;
      s.c[static_cast<std::size_t>(t * N + i)] = rng.uniform(0, 1);
    }
  }
  if (knn)
    knn_graph(s, K);
  else
    random_graph(s, K, 1, rng);
  return s;
}

// A star: node 0 with neighbours 1..n (weights 1/n) at place(t, k) for neighbour k + 1 at frame
// t, every other row empty; node 0's trajectory, the rotations and visibility random. The
// degenerate neighbourhoods of the hard cases (collinear, coincident, a single neighbour).
template <class Place>
Scene<double> star_scene(Index T, Index n, Rng& rng, Place&& place) {
  Scene<double> s = random_scene(T, n + 1, n, rng);
  std::fill(s.idx.begin(), s.idx.end(), -1);
  std::fill(s.w.begin(), s.w.end(), 0.0);
  for (Index k = 0; k < n; ++k) {
    s.idx[static_cast<std::size_t>(k)] = static_cast<std::int32_t>(k + 1);
    s.w[static_cast<std::size_t>(k)] = 1.0 / double(n);
  }
  for (Index t = 0; t < T; ++t)
    for (Index k = 0; k < n; ++k) s.set_pos(t, k + 1, place(t, k));
  return s;
}

// Node i loses its neighbours (its row of the graph empty: −1, weight 0); edges into it stay.
inline void isolate_node(Scene<double>& s, Index i) {
  for (Index k = 0; k < s.K; ++k) {
    s.idx[static_cast<std::size_t>(i * s.K + k)] = -1;
    s.w[static_cast<std::size_t>(i * s.K + k)] = 0.0;
  }
}

// A random scene (6 frames, 6 nodes, each with its 3 nearest as neighbours) whose node 0 and its
// first neighbour coincide at frames 1 and 4: zero-length edges. Every neighbourhood keeps a
// point elsewhere (3 distinct neighbours), so that an edge, not a whole neighbourhood, has
// length 0 (a neighbourhood all at one point is the coincident case, where a fit is pinned and
// the energy not continuous).
inline Scene<double> zero_length_edge_scene(Rng& rng) {
  Scene<double> s = random_scene(6, 6, 3, rng, true);
  const Index j = s.idx[0];
  for (Index t : {Index(1), Index(4)}) s.set_pos(t, j, s.pos(t, 0));
  return s;
}

// A rigidly moving point cloud: x_i^t = Q_t p_i + t v, R_i^t = Q_t R_i with Q_t = Exp(t θ a),
// i.e. a constant angular velocity θ a (radians per frame, world frame) and velocity v. All
// visible; confidences 1; K-nearest-neighbour graph.
inline Scene<double> rigid_scene(Index T, Index N, Index K, double theta, const Vector3<double>& v,
                                 Rng& rng, Vector3<double> axis = Vector3<double>(0.3, -0.5, 0.8)) {
  axis.normalize();
  Scene<double> s;
  s.resize(T, N);
  s.v.assign(s.v.size(), 1);
  s.c.assign(s.c.size(), 1.0);
  std::vector<Vector3<double>> p(static_cast<std::size_t>(N));
  std::vector<Quaternion<double>> r(static_cast<std::size_t>(N));
  for (Index i = 0; i < N; ++i) {
    p[static_cast<std::size_t>(i)] = rng.vec3(1.0);
    r[static_cast<std::size_t>(i)] = rng.quaternion();
  }
  for (Index t = 0; t < T; ++t) {
    const Quaternion<double> Q = so3::exp(Vector3<double>(double(t) * theta * axis));
    for (Index i = 0; i < N; ++i) {
      s.set_pos(t, i, Q * p[static_cast<std::size_t>(i)] + double(t) * v);
      s.set_rot(t, i, Q * r[static_cast<std::size_t>(i)]);
    }
  }
  knn_graph(s, K);
  return s;
}

// The same sequence seen after a global rigid transform x -> Q x + c, R -> Q R.
inline Scene<double> transformed(const Scene<double>& s, const Quaternion<double>& Q,
                                 const Vector3<double>& c) {
  Scene<double> o = s;
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i) {
      o.set_pos(t, i, Q * s.pos(t, i) + c);
      o.set_rot(t, i, Q * s.rot(t, i));
    }
  return o;
}

// Several rigid bodies moving smoothly (rotation + translation), each node with a little
// non-rigid noise, some nodes corrupted: a scene where every confidence factor and Huber's both
// zones are exercised (the benchmarks' scene). K nearest neighbours by frame-0 distance, weights
// 1/K; confidences from node_confidences. Nodes are in random spatial order.
inline Scene<double> rigid_bodies_scene(Index T, Index N, Index K, unsigned seed = 2024) {
  Rng rng(seed);
  Scene<double> s;
  s.resize(T, N);
  s.v.assign(s.v.size(), 1);
  s.c.assign(s.c.size(), 1.0);
  const int bodies = 12;
  std::vector<Vector3<double>> centre, spin, vel;
  for (int b = 0; b < bodies; ++b) {
    centre.push_back(rng.vec3(2.0));
    spin.push_back(rng.vec3(0.03));
    vel.push_back(rng.vec3(0.01));
  }
  for (Index i = 0; i < N; ++i) {
    const int b = static_cast<int>(i % bodies);
    const Vector3<double> p = centre[b] + rng.vec3(0.4);
    const Quaternion<double> r0 = rng.quaternion();
    const bool corrupted = rng.uniform(0, 1) < 0.02;
    for (Index t = 0; t < T; ++t) {
      const Quaternion<double> Q = so3::exp(Vector3<double>(double(t) * spin[b]));
      Vector3<double> x = Q * (p - centre[b]) + centre[b] + double(t) * vel[b] + rng.vec3(0.002);
      if (corrupted) x += rng.vec3(0.03);
      s.set_pos(t, i, x);
      s.set_rot(t, i, Q * r0 * so3::exp(rng.vec3(0.01)));
      s.v[static_cast<std::size_t>(t * N + i)] = rng.uniform(0, 1) < 0.95 ? 1 : 0;
    }
  }
  knn_graph(s, K);
  std::vector<double> c(s.v.size());
  node_confidences<double>(s.positions(), s.visibility(), s.graph(), {}, {c.data(), s.T, s.N});
  s.c = c;
  return s;
}

// LRM options with Huber threshold δ_H = huber_delta and ω detached or not: the pair of settings
// the LRM tests sweep (small δ_H reaches both Huber branches; detach_omega drops ω's dependence
// on the positions), other options at their defaults.
inline LrmOptions lrm_options(double huber_delta, bool detach_omega) {
  LrmOptions o;
  o.huber_delta = huber_delta;
  o.detach_omega = detach_omega;
  return o;
}

}  // namespace smg::test
