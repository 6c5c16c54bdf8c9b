// Compiles examples/trainer/priors.cpp into test_trainer (see examples/CMakeLists.txt).
#include "trainer/priors.cpp"
