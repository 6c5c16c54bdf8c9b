// examples/trainer/layouts.cpp — which layout a scene folder is in, and the reader for it
// (layouts.hpp, docs/data.md).
#include "trainer/layouts.hpp"

#include <filesystem>
#include <string>
#include <vector>

#include "trainer/layout_io.hpp"

namespace trainer {

namespace {

namespace fs = std::filesystem;

// A *bootstapir*.npz file directly in the folder (MoSca's Saved2D globs "*<key>*.npz").
bool layouts_has_bootstapir(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.find("bootstapir") != std::string::npos && name.size() > 4 && name.compare(name.size() - 4, 4, ".npz") == 0)
      return true;
  }
  return false;
}

}  // namespace

const char* data_layout_description(DataLayout layout) {
  switch (layout) {
    case DataLayout::som:
      return "Shape-of-Motion (flow3d_preprocessed/: 1x images, 2d_tracks/1x; the COLMAP cameras colmap/sparse with "
             "aligned_depth_anything_colmap/1x where both are there, else the Nerfies camera/ with "
             "aligned_depth_anything_lidar/1x or lidar depth/1x)";
    case DataLayout::mosca: return "MoSca (images/, sensor_depth/ dep, cameras/, *bootstapir*.npz tracks, epi/error masks)";
    case DataLayout::dycheck: break;
  }
  return "Dycheck + priors (2x images, depth/2x, priors/tracks.npz)";
}

DataLayout detect_data_layout(const std::string& dir) {
  const fs::path d(dir);
  using layout_io::has_file;
  using layout_io::has_folder;
  if (!has_folder(dir, "")) throw DataError(dir + ": not a folder");
  const bool som = has_folder(dir, "flow3d_preprocessed");
  const bool mosca = has_folder(dir, "sensor_depth") && has_folder(dir, "cameras") && layouts_has_bootstapir(d);
  const bool ours_tracks = has_file(dir, "priors/tracks.npz");
  if (som && mosca)
    throw DataError(dir + ": ambiguous scene folder: it holds both flow3d_preprocessed/ (Shape-of-Motion) and "
                          "sensor_depth/ + cameras/ + *bootstapir*.npz (MoSca)");
  if ((som || mosca) && ours_tracks)
    throw DataError(dir + ": ambiguous scene folder: it holds priors/tracks.npz (Dycheck + priors) and " +
                    (som ? "flow3d_preprocessed/ (Shape-of-Motion)" : "sensor_depth/ + cameras/ + *bootstapir*.npz (MoSca)"));
  if (som) return DataLayout::som;
  if (mosca) return DataLayout::mosca;
  if (has_file(dir, "priors") || has_file(dir, "splits") || has_file(dir, "camera")) return DataLayout::dycheck;
  throw DataError(dir + ": not a scene folder: looked for flow3d_preprocessed/ (Shape-of-Motion), sensor_depth/ + cameras/ "
                        "+ *bootstapir*.npz (MoSca), and priors/, splits/ or camera/ (Dycheck + priors)");
}

DycheckScene read_data_scene(const std::string& dir, DataLayout* layout_out) {
  const DataLayout layout = detect_data_layout(dir);
  if (layout_out) *layout_out = layout;
  switch (layout) {
    case DataLayout::som: return read_som(dir);
    case DataLayout::mosca: return read_mosca(dir);
    case DataLayout::dycheck: break;
  }
  return read_dycheck(dir);
}

}  // namespace trainer
