// Compiles examples/trainer/pipeline.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/pipeline.cpp"
