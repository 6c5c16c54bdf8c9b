// smg/core/version.hpp — library version (CMakeLists.txt reads SMG_VERSION_STRING from here).
#pragma once

#include "smg/core/config.hpp"

#define SMG_VERSION_MAJOR 0
#define SMG_VERSION_MINOR 1
#define SMG_VERSION_PATCH 0
#define SMG_VERSION_STRING "0.1.0"
