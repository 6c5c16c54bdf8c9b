// smg/energy/one_term.hpp — what every one-term operator (accel.hpp, angle.hpp, carap.hpp,
// confidence.hpp, lrm.hpp, relrot.hpp) is made of: its arguments' views and validators, its
// options, the workspace, and the driver it calls through (driver.hpp, detail::drive_one_term).
// A one-term operator includes this and its term header (energy/terms/*.hpp), so a new term's
// operator starts from two includes (docs/contributing.md, "Adding a term").
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/parallel.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/driver.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/validate.hpp"
#include "smg/energy/workspace.hpp"
#include "smg/graph/neighbors.hpp"
