// smg/skin.hpp — everything in smg/skin: skinning drivers and distance-aware weights,
// dual-quaternion blending (and LBS for comparison) with Jacobians and a batched backward.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core.hpp"
#include "smg/skin/blend.hpp"
#include "smg/skin/blend_point.hpp"
#include "smg/skin/drivers.hpp"
#include "smg/skin/skin_views.hpp"
#include "smg/skin/weights.hpp"
#include "smg/skin/weights_point.hpp"
