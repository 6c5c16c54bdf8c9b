// examples/trainer/ply.hpp — the trained Gaussians of every frame as 3D Gaussian Splatting PLY
// files (OUT/ply/frame_<t>.ply, flag --ply; docs/trainer.md, "Per-frame PLY").
//
// The layout is the one the original 3DGS code writes (GaussianModel.save_ply) for spherical-
// harmonics degree 0, which its viewers and the web viewers built on it read:
//   format binary_little_endian 1.0, one element `vertex` with 17 float properties
//   x y z nx ny nz f_dc_0 f_dc_1 f_dc_2 opacity scale_0 scale_1 scale_2 rot_0 rot_1 rot_2 rot_3
// * position in the trainer's world frame; normals 0 (3DGS writes zeros too);
// * colour as the degree-0 SH coefficient: f_dc = (rgb - 0.5) / C0, C0 = 0.28209479177387814,
//   so that 3DGS's colour C0 * f_dc + 0.5 is the trainer's RGB;
// * opacity as a logit and scale as log(sigma), the trainer's own parameters;
// * rotation as a unit quaternion (w, x, y, z).
// Rows: the static Gaussians, then the dynamic ones posed at frame t by the library's DQB
// (pose_model: smg::skin_blend), i.e. what the trainer renders at frame t.
#pragma once

#include <string>
#include <vector>

#include "trainer/gaussians.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

// The SH degree-0 constant of 3DGS (sh_utils.py, C0).
inline constexpr double kShC0 = 0.28209479177387814;

// Writes `G` Gaussians (means [G][3], quats [G][4] (w, x, y, z), log_scales [G][3], opacity
// logits [G], colors [G][3] RGB) as one 3DGS PLY file. Throws std::runtime_error naming the file
// when it cannot be written.
void write_gaussians_ply(const std::string& path, const std::vector<float>& means, const std::vector<float>& quats,
                         const std::vector<float>& log_scales, const std::vector<float>& opacity,
                         const std::vector<float>& colors);

// OUT/ply/frame_<t>.ply for every frame t = 0 .. T-1 of the nodes (t without leading zeros),
// after removing the frame_*.ply files already there. Returns the paths written.
std::vector<std::string> write_ply_frames(const std::string& out, const GaussianModel<float>& model,
                                          const Nodes& nodes);

}  // namespace trainer
