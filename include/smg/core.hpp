// smg/core.hpp — everything in smg/core: views, validation, SO(3), dual quaternions, parallel.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/dual_quaternion.hpp"
#include "smg/core/parallel.hpp"
#include "smg/core/quaternion.hpp"
#include "smg/core/quaternion_manifold.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/rotation_gradient_batch.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/so3.hpp"
#include "smg/core/status.hpp"
#include "smg/core/types.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/version.hpp"
#include "smg/core/views.hpp"
