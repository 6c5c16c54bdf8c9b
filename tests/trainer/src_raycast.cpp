// Compiles examples/trainer/raycast.cpp into test_trainer (see examples/CMakeLists.txt).
#include "trainer/raycast.cpp"
