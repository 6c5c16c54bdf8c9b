// Compiles examples/trainer/image_io.cpp into test_pipeline (see examples/CMakeLists.txt).
#include "trainer/image_io.cpp"
