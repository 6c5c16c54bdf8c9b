// Tests of smg/graph/neighbors.hpp: the neighbour-table view and its validation.
#include <doctest/doctest.h>

#include <cstdint>
#include <limits>
#include <vector>

#include "smg/graph/neighbors.hpp"

TEST_CASE("NeighborsView degree and validate_neighbors") {
  std::vector<std::int32_t> idx = {1, 2, -1,   // node 0
                                   0, -1, -1,  // node 1
                                   -1, -1, -1};
  std::vector<double> w = {0.5, 0.5, 0, 1, 0, 0, 0, 0, 0};
  const smg::NeighborsView<double> g(idx.data(), w.data(), 3, 3);
  CHECK(g.degree(0) == 2);
  CHECK(g.degree(1) == 1);
  CHECK(g.degree(2) == 0);
  CHECK(smg::validate_neighbors(g, 3).is_ok());
  CHECK(smg::validate_neighbors(g, 4).message() ==
        "graph: expected indices and weights of shape [N=4][K], got [3][3] and [3][3]");

  idx[1] = 0;  // self edge
  CHECK(smg::validate_neighbors(g, 3).message() == "graph: entry [i=0][k=1] is a self edge");
  idx[1] = 3;
  CHECK(smg::validate_neighbors(g, 3).message() == "graph: entry [i=0][k=1] is out of range: 3");
  idx[1] = 2;
  idx[4] = -1;
  idx[5] = 2;  // neighbour after padding
  w[5] = 0.1;
  CHECK(smg::validate_neighbors(g, 3).message() == "graph: entry [i=1][k=2] is a neighbour after -1 padding");
  idx[5] = -1;
  CHECK(smg::validate_neighbors(g, 3).message() == "graph: entry [i=1][k=2] is padding (-1) with a nonzero weight");
  w[5] = 0;
  w[0] = std::numeric_limits<double>::quiet_NaN();
  CHECK(smg::validate_neighbors(g, 3).message() ==
        "graph: entry [i=0][k=0] has a weight that is negative or not finite");
}
