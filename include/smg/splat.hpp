// smg/splat.hpp — everything in smg/splat.
#pragma once

#include "smg/core.hpp"
