// smg_assert_probe MODE — misuses a view or an entry point on purpose, built with
// SMG_ENABLE_ASSERTS, so that tests/api/test_asserts.cpp can check that a debug build fails
// loudly (one "smg: assertion failed" line, abort) instead of writing out of bounds.
#include <cstdio>
#include <string>
#include <vector>

#include "smg/smg.hpp"

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  const smg::Index T = 4, N = 3;
  std::vector<double> x(T * N * 3, 0.0), q(T * N * 4, 0.0), small(T * 2 * 3, 0.0);
  for (smg::Index k = 0; k < T * N; ++k) {
    q[k * 4] = 1;
    x[k * 3] = double(k);
  }
  std::vector<std::int32_t> idx = {1, 2, 0, 2, 0, 1};
  std::vector<double> w(6, 0.5);
  const smg::NeighborsView<double> g(idx.data(), w.data(), N, 2);
  const smg::PositionsView<const double> X(x.data(), T, N);
  const smg::QuaternionsView<const double> Q(q.data(), T, N);
  if (mode == "view") {
    std::printf("%g\n", X(T, 0)(0));  // frame T does not exist
  } else if (mode == "carap") {
    // A gradient buffer for 2 nodes where there are 3.
    smg::carap<double>(X, Q, {}, g, smg::CarapOptions{}, {small.data(), T, 2});
  } else if (mode == "lrm") {
    smg::lrm<double>(X, {}, g, smg::LrmOptions{}, {small.data(), T, 2});
  } else if (mode == "ok") {
    std::printf("%g\n", double(smg::carap<double>(X, Q, {}, g, smg::CarapOptions{})));
    return 0;
  }
  std::printf("no assertion fired\n");
  return 3;
}
