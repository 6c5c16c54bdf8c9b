// Compiles examples/trainer/scene.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/scene.cpp"
