// smg_assert_probe MODE — misuses a view or an operator (MODE: its name) on purpose, built with
// SMG_ENABLE_ASSERTS, so that tests/api/test_asserts.cpp can check that a debug build fails
// loudly (one "smg: assertion failed" line, abort) instead of writing out of bounds.
#include <cstdio>
#include <string>
#include <vector>

#include "smg/smg.hpp"
#include "support/operators.hpp"

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
  } else if (mode == "ok") {
    std::printf("%g\n", double(smg::carap<double>(X, Q, {}, g, smg::CarapOptions{})));
    return 0;
  }
  // Each operator of tests/support/operators.hpp, its name as the mode: output buffers for 2 nodes
  // where there are 3.
  smg::test::for_each_operator([&](auto op) {
    if (mode != op.name) return;
    std::vector<double> small_r(small.size(), 0.0), small_c(T * 2, 0.0);
    op.run(smg::test::OperatorInputs<double>{X, Q, {}, {}, g},
           {{small.data(), T, 2}, {small_r.data(), T, 2}, {small_c.data(), T, 2}});
  });
  std::printf("no assertion fired\n");
  return 3;
}
