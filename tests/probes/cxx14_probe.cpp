// Compiled as C++14 by the cxx14_is_rejected test: smg must stop at one clear message.
#include "smg/smg.hpp"
int main() { return 0; }
