// tests/graph/synthetic_scene.hpp — seeded synthetic scenes for the graph tests and benchmark:
// rigid objects (points on sphere surfaces) that translate and rotate through a shared volume
// so that they pass close to each other, tracks visible over random windows with dropouts, and
// per-frame feature samples = the object's feature direction + noise, with a fraction of
// outlier samples in random directions.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "smg/core/types.hpp"

namespace smg::test {

struct SceneOptions {
  Index nodes = 1000;
  Index frames = 50;
  int objects = 8;
  Index channels = 0;              // feature channels (0: no feature samples)
  double extent = 3.0;             // objects move inside [-extent, extent]^3
  double speed = 1.0;              // scales the motion per frame
  double dropout = 0.1;            // probability that a frame inside the window is invisible
  double min_window = 0.5;         // each track is visible over a window of >= this fraction of T
  double feature_noise = 0.2;
  double outlier_fraction = 0.05;  // feature samples replaced by random directions
  std::uint64_t seed = 1;
};

template <class S>
struct GraphScene {
  Index T = 0, N = 0, C = 0;
  std::vector<S> positions;            // [T][N][3]
  std::vector<std::uint8_t> visibility;  // [T][N]
  std::vector<S> samples;              // [T][N][C]
  std::vector<int> object;             // [N]
  std::vector<S> object_features;      // [objects][C], unit
};

template <class S>
GraphScene<S> make_scene(const SceneOptions& o) {
  GraphScene<S> sc;
  sc.T = o.frames;
  sc.N = o.nodes;
  sc.C = o.channels;
  std::mt19937_64 g(o.seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0), u01(0.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  struct Object {
    Eigen::Vector3d a, b, axis;
    double omega, phase, spin, radius;
  };
  std::vector<Object> obj(static_cast<std::size_t>(o.objects));
  for (auto& ob : obj) {
    ob.a = Eigen::Vector3d(u(g), u(g), u(g)) * o.extent * 0.5;
    ob.b = Eigen::Vector3d(u(g), u(g), u(g)) * o.extent * 0.5;
    ob.axis = Eigen::Vector3d(n01(g), n01(g), n01(g)).normalized();
    ob.omega = (0.5 + u01(g)) * 2.0 * M_PI / std::max<double>(1.0, static_cast<double>(o.frames)) * o.speed;
    ob.phase = u01(g) * 2.0 * M_PI;
    ob.spin = u(g) * 0.05 * o.speed;
    ob.radius = 0.3 + 0.3 * u01(g);
  }
  std::vector<Eigen::Vector3d> local(static_cast<std::size_t>(o.nodes));
  sc.object.resize(static_cast<std::size_t>(o.nodes));
  std::vector<Index> w0(static_cast<std::size_t>(o.nodes)), w1(static_cast<std::size_t>(o.nodes));
  for (Index i = 0; i < o.nodes; ++i) {
    const int k = static_cast<int>(u01(g) * o.objects) % o.objects;
    sc.object[static_cast<std::size_t>(i)] = k;
    local[static_cast<std::size_t>(i)] =
        Eigen::Vector3d(n01(g), n01(g), n01(g)).normalized() * obj[static_cast<std::size_t>(k)].radius;
    const double len = o.min_window + (1.0 - o.min_window) * u01(g);
    const Index L = std::max<Index>(1, static_cast<Index>(std::round(len * static_cast<double>(o.frames))));
    const Index start = static_cast<Index>(u01(g) * static_cast<double>(o.frames - L + 1));
    w0[static_cast<std::size_t>(i)] = std::min(start, o.frames - 1);
    w1[static_cast<std::size_t>(i)] = std::min(o.frames, start + L);
  }
  sc.positions.resize(static_cast<std::size_t>(o.frames * o.nodes * 3));
  sc.visibility.resize(static_cast<std::size_t>(o.frames * o.nodes));
  for (Index t = 0; t < o.frames; ++t) {
    std::vector<Eigen::Matrix3d> R(obj.size());
    std::vector<Eigen::Vector3d> c(obj.size());
    for (std::size_t k = 0; k < obj.size(); ++k) {
      const auto& ob = obj[k];
      const double s = std::sin(ob.omega * static_cast<double>(t) + ob.phase);
      c[k] = ob.a + ob.b * s;
      R[k] = Eigen::AngleAxisd(ob.spin * static_cast<double>(t), ob.axis).toRotationMatrix();
    }
    for (Index i = 0; i < o.nodes; ++i) {
      const auto k = static_cast<std::size_t>(sc.object[static_cast<std::size_t>(i)]);
      const Eigen::Vector3d x = c[k] + R[k] * local[static_cast<std::size_t>(i)];
      for (int d = 0; d < 3; ++d) sc.positions[static_cast<std::size_t>((t * o.nodes + i) * 3 + d)] = static_cast<S>(x(d));
      const bool in = t >= w0[static_cast<std::size_t>(i)] && t < w1[static_cast<std::size_t>(i)];
      sc.visibility[static_cast<std::size_t>(t * o.nodes + i)] = in && u01(g) >= o.dropout ? 1 : 0;
    }
  }
  if (o.channels > 0) {
    const Index C = o.channels;
    sc.object_features.resize(static_cast<std::size_t>(o.objects * C));
    for (int k = 0; k < o.objects; ++k) {
      Eigen::VectorXd f(C);
      for (Index c = 0; c < C; ++c) f(c) = n01(g);
      f.normalize();
      for (Index c = 0; c < C; ++c) sc.object_features[static_cast<std::size_t>(k * C + c)] = static_cast<S>(f(c));
    }
    sc.samples.resize(static_cast<std::size_t>(o.frames * o.nodes * C));
    Eigen::VectorXd s(C);
    for (Index t = 0; t < o.frames; ++t)
      for (Index i = 0; i < o.nodes; ++i) {
        const auto k = static_cast<std::size_t>(sc.object[static_cast<std::size_t>(i)]);
        const bool outlier = u01(g) < o.outlier_fraction;
        for (Index c = 0; c < C; ++c)
          s(c) = outlier ? n01(g)
                         : static_cast<double>(sc.object_features[k * static_cast<std::size_t>(C) + static_cast<std::size_t>(c)]) +
                               o.feature_noise * n01(g) / std::sqrt(static_cast<double>(C));
        for (Index c = 0; c < C; ++c)
          sc.samples[static_cast<std::size_t>((t * o.nodes + i) * C + c)] = static_cast<S>(s(c));
      }
  }
  return sc;
}

}  // namespace smg::test
