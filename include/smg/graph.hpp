// smg/graph.hpp — everything in smg/graph.
#pragma once

#include "smg/core.hpp"
#include "smg/graph/neighbors.hpp"
