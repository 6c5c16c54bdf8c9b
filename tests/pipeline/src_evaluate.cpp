// Compiles examples/trainer/evaluate.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/evaluate.cpp"
