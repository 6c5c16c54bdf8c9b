// examples/trainer/dycheck.hpp — a scene on disk in the Dycheck iPhone layout plus SMG's priors
// (docs/data.md): reading with full validation, and writing (the exporter of the procedural
// scene uses the writer, so both sides of the format live in one place).
//
// Layout (docs/data.md sections 1 and 2), read at factor 2 ("2x"):
//   camera/<frame>.json, rgb/2x/<frame>.png, depth/2x/<frame>.npy (training frames),
//   covisible/2x/val/<frame>.png (validation frames), splits/{train,val}.json,
//   priors/tracks.npz, priors/masks/<frame>.png, priors/features/<frame>.npy.
// Frame names are "{camera}_{time:05d}". Cameras are stored at 1x in the files and converted
// here: focal length and principal point halved, image size halved and rounded. Pixel (i, j) has
// its centre at (i + 0.5, j + 0.5) in both the files and trainer::Camera.
//
// Every problem found while reading throws DataError with one line "<file>: <problem>" (the file
// as a path under the scene folder), before anything is trained. Extra keys in the JSON files and
// extra files in the folders are tolerated.
#pragma once

#include <string>

#include "trainer/dycheck_scene.hpp"  // DycheckScene, DataError

namespace trainer {

// Reads and validates a scene (docs/data.md). Throws DataError ("<file>: <problem>") on a missing
// or unreadable file, an inconsistent one (sizes, frame names, time ids, splits), non-zero
// distortion, a non-finite value, depth < 0, a track far outside the image, a feature map of a
// different size than the others, or C outside 1 .. 64.
DycheckScene read_dycheck(const std::string& dir, const DycheckReadOptions& options = {});

// Writes `scene` in the layout into `dir` (created if missing; existing files of the layout are
// replaced): camera JSONs at 1x (the inverse of the 2x conversion: focal length and principal
// point doubled, size doubled), 8-bit PNGs, float32 depth [H,W,1], splits, dataset.json,
// scene.json, tracks.npz (uncompressed), masks, features (float32 [h,w,C]). Frames whose
// has_mask / has_features is 0 get no file. Throws DataError naming the file it cannot write.
void write_dycheck(const std::string& dir, const DycheckScene& scene);

}  // namespace trainer
