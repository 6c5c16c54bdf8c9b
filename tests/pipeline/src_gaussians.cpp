// Compiles examples/trainer/gaussians.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/gaussians.cpp"
