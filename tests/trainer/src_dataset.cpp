// Compiles examples/trainer/dataset.cpp into test_trainer (see examples/CMakeLists.txt).
#include "trainer/dataset.cpp"
