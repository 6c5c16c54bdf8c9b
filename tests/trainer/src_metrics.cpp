// Compiles examples/trainer/metrics.cpp into test_trainer (see examples/CMakeLists.txt).
#include "trainer/metrics.cpp"
