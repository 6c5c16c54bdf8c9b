// Compiles examples/trainer/image_io.cpp into test_trainer (see examples/CMakeLists.txt).
#include "trainer/image_io.cpp"
