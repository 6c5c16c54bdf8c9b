// Compiles examples/trainer/priors.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/priors.cpp"
