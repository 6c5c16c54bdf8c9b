// Compiles examples/trainer/pictures.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/pictures.cpp"
