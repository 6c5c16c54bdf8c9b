// Compiles examples/trainer/nodes.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/nodes.cpp"
