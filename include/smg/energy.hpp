// smg/energy.hpp — everything in smg/energy: node confidences, C-ARAP, LRM and plain ARAP with
// exact gradients (energy + gradient into caller buffers) and residual + Jacobian forms.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core.hpp"
#include "smg/core/quaternion_manifold.hpp"
#include "smg/energy/arap.hpp"
#include "smg/energy/carap.hpp"
#include "smg/energy/carap_directed.hpp"
#include "smg/energy/carap_residuals.hpp"
#include "smg/energy/carap_term.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/confidence.hpp"
#include "smg/energy/confidence_term.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/lrm.hpp"
#include "smg/energy/lrm_residuals.hpp"
#include "smg/energy/lrm_term.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/regularizers.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/energy/workspace.hpp"
