// smg/energy.hpp — everything in smg/energy.
#pragma once

#include "smg/core.hpp"
