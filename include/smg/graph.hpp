// smg/graph.hpp — everything in smg/graph: trajectory distances, exact trajectory KNN,
// semantic descriptors, the gated semantic motion graph with topology weights, and adaptive
// node selection (docs/math/graph.md).
#pragma once

#include "smg/core/config.hpp"

#include "smg/core.hpp"
#include "smg/graph/descriptor.hpp"
#include "smg/graph/knn.hpp"
#include "smg/graph/neighbors.hpp"
#include "smg/graph/node_order.hpp"
#include "smg/graph/node_selection.hpp"
#include "smg/graph/point_knn.hpp"
#include "smg/graph/semantic_graph.hpp"
#include "smg/graph/trajectory_distance.hpp"
