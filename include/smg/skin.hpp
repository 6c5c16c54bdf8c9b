// smg/skin.hpp — everything in smg/skin.
#pragma once

#include "smg/core.hpp"
