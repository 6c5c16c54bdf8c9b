// Quick start 1: wrap your own arrays in views, validate them, read a Status.
#include <cstdint>
#include <cstdio>
#include <limits>
#include <vector>

#include <smg/smg.hpp>

int main() {
  // Your memory, C-order, as a NumPy array or a contiguous PyTorch tensor lays it out:
  // node positions [T][N][3] and rotations [T][N][4] as (w, x, y, z).
  const smg::Index T = 2, N = 3;
  std::vector<double> x = {0, 0, 0,  1, 0, 0,  2, 0, 0,     // frame 0
                           0, 0, 1,  1, 0, 1,  2, 0, 1};    // frame 1
  std::vector<double> q(T * N * 4, 0.0);
  for (smg::Index k = 0; k < T * N; ++k) q[k * 4] = 1.0;    // identity rotations
  std::vector<std::uint8_t> vis(T * N, 1);                  // visibility [T][N], 0 or 1

  // A view is a pointer and sizes, never a copy. A view of non-const elements may be written
  // (gradients, outputs); every entry point also takes it where it reads an input.
  smg::PositionsView<double> positions(x.data(), T, N);
  smg::QuaternionsView<double> rotations(q.data(), T, N);
  smg::VisibilityView<std::uint8_t> visibility(vis.data(), T, N);
  smg::PositionsView<const double> read_only = positions;   // mutable -> const converts
  std::printf("node 1 at frame 1: (%g, %g, %g)\n", read_only(1, 1).x(), read_only(1, 1).y(),
              read_only(1, 1).z());

  // validate_* return smg::Status: true when ok, else message() names the argument and the
  // first offending element. The computations themselves never check (undefined on bad input).
  bool ok = true;
  auto expect = [&ok](const smg::Status& s, bool want_ok) {
    if (s)
      std::printf("  ok\n");
    else
      std::printf("  error: %s\n", s.message().c_str());
    ok = ok && (static_cast<bool>(s) == want_ok);
  };
  expect(smg::validate_positions(positions, T, N), true);
  expect(smg::validate_quaternions(rotations, T, N), true);
  expect(smg::validate_visibility(visibility, T, N), true);

  // Quaternions: any finite nonzero (w, x, y, z) is accepted by default, since the entry points
  // normalise on entry; QuaternionNorm::require_unit also rejects unnormalised ones.
  q[4] = 2.0;                                               // node 1, frame 0: |q| = 2
  expect(smg::validate_quaternions(rotations, T, N), true);
  expect(smg::validate_quaternions(rotations, T, N, smg::QuaternionNorm::require_unit), false);
  q[4] = 0.0;                                               // the zero quaternion: never valid
  expect(smg::validate_quaternions(rotations, T, N), false);
  x[4] = std::numeric_limits<double>::quiet_NaN();          // node 1, frame 0, y
  expect(smg::validate_positions(positions, T, N), false);
  vis[2] = 2;
  expect(smg::validate_visibility(visibility, T, N), false);

  // The graph: [N][K] neighbour indices (int32, or int64 as PyTorch makes them, read in place)
  // and [N][K] topology weights; -1 pads a row.
  std::vector<std::int64_t> idx = {1, 2,  0, 2,  1, -1};
  std::vector<double> w = {0.5, 0.5,  0.5, 0.5,  1.0, 0.0};
  const smg::NeighborsView<double, std::int64_t> graph(idx.data(), w.data(), N, 2);
  expect(smg::validate_neighbors(graph, N), true);
  idx[0] = 0;                                               // a self edge
  expect(smg::validate_neighbors(graph, N), false);

  std::printf("quickstart views: %s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
