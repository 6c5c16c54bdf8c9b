// tests/trainer/fixture.hpp — small scenes shared by the trainer tests (built once per process).
#pragma once

#include "trainer/dataset.hpp"
#include "trainer/priors.hpp"
#include "trainer/raycast.hpp"
#include "trainer/scene.hpp"

namespace trainer::test {

// A small but complete configuration: 10 frames at 80x60, 600 tracks, one ray per pixel (the
// tests also run under the sanitizers).
inline DatasetConfig small_config(std::uint64_t seed = 3) {
  DatasetConfig c;
  c.scene.seed = seed;
  c.scene.frames = 10;
  c.scene.width = 80;
  c.scene.height = 60;
  c.priors.tracks = 600;
  c.supersample = 1;
  return c;
}

inline const Dataset& small_dataset() {
  static const Dataset d = make_dataset(small_config());
  return d;
}

// Independent signed distance functions (not the ray caster's code) for cross-checks, in the
// shape's local frame.
inline double shape_sdf(const Shape& s, const Eigen::Vector3d& p) {
  switch (s.kind) {
    case ShapeKind::sphere:
      return p.norm() - s.size.x();
    case ShapeKind::box: {
      const Eigen::Vector3d q = p.cwiseAbs() - s.size;
      return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
    }
    case ShapeKind::capsule: {
      const double x = std::min(std::max(p.x(), 0.0), s.size.x());
      return (p - Eigen::Vector3d(x, 0, 0)).norm() - s.size.y();
    }
    case ShapeKind::rectangle:
      break;
  }
  return 0.0;
}

}  // namespace trainer::test
