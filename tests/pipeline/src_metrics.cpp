// Compiles examples/trainer/metrics.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/metrics.cpp"
