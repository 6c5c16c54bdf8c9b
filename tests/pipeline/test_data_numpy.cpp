// smg_trainer --data on files as other numpy code writes them (issue 23): tracks.npz from
// np.savez_compressed, depth in Fortran order, no feature files; and the scenes it refuses: exit
// 2, one escaped line naming the file or the cause, and no OUT folder.
#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "support/files.hpp"
#include "support/run_program.hpp"
#include "trainer/image.hpp"
#include "trainer/image_io.hpp"

#ifdef SMG_TRAINER_PATH
namespace {

namespace fs = std::filesystem;

smg::test::ProgramRun numpy_scene_trainer_run(const std::string& args) {
  return smg::test::run_program(SMG_TRAINER_PATH, args, "smg_test_pipeline_data_numpy_io");
}

bool numpy_scene_has_numpy() { return std::system("/usr/bin/python3 -c 'import numpy' >/dev/null 2>&1") == 0; }

// Rewrites every depth/2x/*.npy of `scene` in Fortran order by hand: the C-order file's header
// with 'fortran_order': True and the [H, W, 1] float32 values column after column (what np.save
// writes for np.asfortranarray(depth)).
void numpy_scene_fortran_depth(const fs::path& scene, int width, int height) {
  for (const auto& e : fs::directory_iterator(scene / "depth/2x")) {
    const std::string c = smg::test::slurp(e.path());
    const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height), head = c.size() - 4 * n;
    std::string f = c.substr(0, head);
    const auto flag = f.find("False,");
    REQUIRE(flag != std::string::npos);
    f.replace(flag, 6, "True, ");
    for (std::size_t x = 0; x < static_cast<std::size_t>(width); ++x)
      for (std::size_t y = 0; y < static_cast<std::size_t>(height); ++y)
        f += c.substr(head + (y * static_cast<std::size_t>(width) + x) * 4, 4);
    smg::test::write_bytes(e.path(), f);
  }
}

}  // namespace

TEST_CASE("smg_trainer --data: numpy's compressed tracks.npz, Fortran-order depth, no feature files") {
  const fs::path scene = fs::temp_directory_path() / "smg_test_pipeline_numpy_scene";
  const fs::path out = fs::temp_directory_path() / "smg_test_pipeline_numpy_out";
  fs::remove_all(scene);
  fs::remove_all(out);
  const int W = 48, H = 36;
  smg::test::ProgramRun r = numpy_scene_trainer_run("--export-dycheck " + scene.string() + " --frames 8 --width " +
                                                    std::to_string(W) + " --height " + std::to_string(H) +
                                                    " --tracks 300 --threads 2 --quiet");
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  fs::remove_all(scene / "priors/features");
  if (numpy_scene_has_numpy()) {
    // numpy itself: tracks.npz compressed, every depth map saved in Fortran order.
    const std::string py =
        "import glob, numpy as np, sys\n"
        "d = sys.argv[1]\n"
        "with np.load(d + '/priors/tracks.npz') as z: a = {k: z[k] for k in z.files}\n"
        "np.savez_compressed(d + '/priors/tracks.npz', **a)\n"
        "for p in glob.glob(d + '/depth/2x/*.npy'): np.save(p, np.asfortranarray(np.load(p)))\n";
    smg::test::write_bytes(scene / "numpy_rewrite.py", py);
    REQUIRE(std::system(("/usr/bin/python3 " + (scene / "numpy_rewrite.py").string() + " " + scene.string()).c_str()) == 0);
    const std::string z = smg::test::slurp(scene / "priors/tracks.npz");
    CHECK(static_cast<unsigned char>(z[8]) == 8);  // the first member is deflated
  } else {
    MESSAGE("no /usr/bin/python3 with numpy: tracks.npz stays stored, depth is made Fortran-order here");
    numpy_scene_fortran_depth(scene, W, H);
  }
  CHECK(smg::test::slurp(scene / "depth/2x/0_00003.npy").find("'fortran_order': True") != std::string::npos);

  r = numpy_scene_trainer_run("--data " + scene.string() +
                              " --quick --stage1-iters 20 --stage2-iters 10 --threads 2 --quiet --out " + out.string());
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  // The one note (--quiet: nothing else on stderr), and a geometric graph.
  CHECK(smg::test::count_lines(r.err) == 1);
  CHECK(r.err.find("smg_trainer: note: no feature files") == 0);
  CHECK(r.err.find("the graph is geometric") != std::string::npos);
  const std::string metrics = smg::test::slurp(out / "metrics.json");
  CHECK(metrics.find("\"semantic_graph\":false") != std::string::npos);
  CHECK(metrics.find("\"gate_removed_edges\":0") != std::string::npos);
  CHECK(fs::exists(out / "renders/1_00000.png"));
  {
    // The accepted scene's path is echoed by the progress lines (no --quiet): a control
    // character in it (an ANSI escape) reaches the terminal escaped.
    const fs::path odd = fs::temp_directory_path() / "smg_test_pipeline_numpy_\x1b(B_scene";
    const fs::path odd_out = fs::temp_directory_path() / "smg_test_pipeline_numpy_odd_out";
    fs::remove_all(odd);
    fs::remove_all(odd_out);
    fs::rename(scene, odd);
    const smg::test::ProgramRun p = numpy_scene_trainer_run(
        "--data '" + odd.string() + "' --quick --stage1-iters 2 --stage2-iters 1 --threads 2 --out " + odd_out.string());
    fs::rename(odd, scene);
    fs::remove_all(odd_out);
    CAPTURE(p.err);
    CHECK(p.code == 0);
    CHECK((p.out + p.err).find("_\\x1b(B_scene") != std::string::npos);
    CHECK((p.out + p.err).find('\x1b') == std::string::npos);
  }

  // Refused scenes: exit 2, one line naming the file or the cause (without --quiet: stage 0's
  // progress lines are held back until the scene is accepted), no OUT folder.
  const fs::path bad_out = fs::temp_directory_path() / "smg_test_pipeline_numpy_bad_out";
  const auto refused = [&](const std::string& what, const std::string& message) {
    CAPTURE(what);
    fs::remove_all(bad_out);
    const smg::test::ProgramRun b =
        numpy_scene_trainer_run("--data " + scene.string() + " --quick --threads 2 --out " + bad_out.string());
    CAPTURE(b.err);
    CHECK(b.code == 2);
    CHECK(smg::test::count_lines(b.err) == 1);
    CHECK(b.err.find(message) != std::string::npos);
    CHECK(b.err.find('\x1b') == std::string::npos);
    CHECK_FALSE(fs::exists(bad_out));
    return b.err;
  };
  {
    // A member cut short: the recorded compressed size of uv.npy halved in the central directory.
    const std::string good = smg::test::slurp(scene / "priors/tracks.npz");
    std::string z = good;
    const auto cd = z.find(std::string("PK\x01\x02", 4));
    REQUIRE(cd != std::string::npos);
    REQUIRE(z.compare(cd + 46, 6, "uv.npy") == 0);
    const std::uint32_t csize = static_cast<unsigned char>(z[cd + 20]) | (static_cast<unsigned char>(z[cd + 21]) << 8) |
                                (static_cast<std::uint32_t>(static_cast<unsigned char>(z[cd + 22])) << 16);
    const std::uint32_t half = csize / 2;
    for (int k = 0; k < 4; ++k) z[cd + 20 + static_cast<std::size_t>(k)] = static_cast<char>((half >> (8 * k)) & 0xFFu);
    smg::test::write_bytes(scene / "priors/tracks.npz", z);
    refused("truncated member", numpy_scene_has_numpy() ? "priors/tracks.npz: member 'uv.npy': deflate data ends early"
                                                        : "priors/tracks.npz: ");
    smg::test::write_bytes(scene / "priors/tracks.npz", good);
  }
  {
    // Masks without a dynamic pixel: no lifted object track, refused after stage 0's lifting.
    std::vector<fs::path> masks;
    for (const auto& e : fs::directory_iterator(scene / "priors/masks")) masks.push_back(e.path());
    REQUIRE(masks.size() == 8);
    for (const fs::path& m : masks) trainer::write_png(m.string(), trainer::Image(W, H, 1, 0.0f));
    refused("empty masks", "priors/tracks.npz, priors/masks, depth/2x: too few lifted object tracks");
  }
  {
    // Control characters in a frame name (an ANSI escape and a newline) are escaped.
    const std::string split = smg::test::slurp(scene / "splits/train.json");
    std::string bad = split;
    const auto at = bad.find("0_00000");
    REQUIRE(at != std::string::npos);
    bad.replace(at, 7, "0_00000\\u001b[31m\\n");
    smg::test::write_bytes(scene / "splits/train.json", bad);
    const std::string err = refused("control characters", "splits/train.json: frame_names[0] is '0_00000\\x1b[31m\\n'");
    CHECK(err.find('\n') == err.size() - 1);
    smg::test::write_bytes(scene / "splits/train.json", split);
  }
  fs::remove_all(scene);
  fs::remove_all(out);
}
#endif
