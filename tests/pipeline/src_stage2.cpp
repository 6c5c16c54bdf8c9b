// Compiles examples/trainer/stage2.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/stage2.cpp"
