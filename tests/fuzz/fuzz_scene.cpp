// tests/fuzz/fuzz_scene.cpp — the scene folder's top-level files as the readers open them from
// disk: a Nerfies camera JSON (camera/<frame>.json, MoSca's cameras/ and test_cameras/; read at
// 1x and at 2x) and a split file (splits/train.json, splits/val.json). The first byte picks the
// file, the rest is its content, written to a scratch folder of this process.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_target.hpp"
#include "trainer/dycheck.hpp"
#include "trainer/layout_io.hpp"

SMG_FUZZ_TARGET(scene)(const std::uint8_t* data, std::size_t size) {
  namespace fs = std::filesystem;
  static const fs::path root = fs::temp_directory_path() / ("smg_fuzz_scene_" + std::to_string(::getpid()));
  if (size < 1) return 0;
  const int which = data[0] % 3;
  const std::string rel = which == 2 ? "splits/train.json" : "camera/0_00000.json";
  fs::create_directories(root / fs::path(rel).parent_path());
  {
    std::ofstream f(root / rel, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  try {
    if (which == 2) (void)trainer::layout_io::read_train_split(root.string());
    else (void)trainer::layout_io::read_nerfies_camera(root.string(), rel, which + 1);
  } catch (const trainer::DataError&) {
  }
  return 0;
}
