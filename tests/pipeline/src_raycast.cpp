// Compiles examples/trainer/raycast.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/raycast.cpp"
