// smg/splat.hpp — everything in smg/splat: the reference CPU Gaussian splatter (gsplat's
// semantics) with its analytic backward.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core.hpp"
#include "smg/splat/camera.hpp"
#include "smg/splat/gaussians.hpp"
#include "smg/splat/projection.hpp"
#include "smg/splat/render.hpp"
#include "smg/splat/settings.hpp"
#include "smg/splat/sh.hpp"
#include "smg/splat/workspace.hpp"
