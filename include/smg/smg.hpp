// smg/smg.hpp — umbrella header: the whole library.
//
// Each module also has its own umbrella (smg/core.hpp, smg/graph.hpp, smg/energy.hpp,
// smg/skin.hpp, smg/splat.hpp) and every header can be included on its own; include only what
// you use to keep compile times down.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core.hpp"
#include "smg/energy.hpp"
#include "smg/graph.hpp"
#include "smg/skin.hpp"
#include "smg/splat.hpp"
