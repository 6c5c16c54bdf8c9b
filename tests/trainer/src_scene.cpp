// Compiles examples/trainer/scene.cpp into test_trainer (see examples/CMakeLists.txt).
#include "trainer/scene.cpp"
