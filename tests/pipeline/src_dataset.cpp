// Compiles examples/trainer/dataset.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/dataset.cpp"
