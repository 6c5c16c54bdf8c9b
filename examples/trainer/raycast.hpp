// examples/trainer/raycast.hpp — the analytic ray caster that makes the ground truth.
//
// Exact ray/primitive intersections (rectangles, spheres, boxes, capsules) in each body's local
// frame; nothing is shared with the splatter, so fitting the splatter to these images is not an
// inverse crime. Per pixel it writes the anti-aliased colour (the mean of k x k stratified
// sub-pixel rays) and, from the ray through the pixel centre, the depth z, the body id and,
// optionally, the hit point in the body's frame (what tracks and co-visibility are built from).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "smg/core/parallel.hpp"
#include "trainer/camera.hpp"
#include "trainer/image.hpp"
#include "trainer/scene.hpp"

namespace trainer {

// Nearest intersection along a ray.
struct Hit {
  double distance = 0;                                      // along the (unit) ray direction
  int body = -1;                                            // -1: nothing hit
  Eigen::Vector3d local = Eigen::Vector3d::Zero();          // hit point, body frame
  Eigen::Vector3d normal_local = Eigen::Vector3d::UnitZ();  // outward unit normal, body frame
};

// Ray (in the shape's frame, unit direction) against one primitive: the smallest distance in
// (t_min, t_max) and the outward normal there. A rectangle's normal is always +z (one face, hit
// from either side); a ray starting inside a closed shape hits its far side. Returns false on a
// miss.
bool intersect_shape(const Shape& shape, const Ray& local_ray, double t_min, double t_max,
                     double* distance, Eigen::Vector3d* normal_local);

// Nearest hit of a world ray with the scene at integer frame t within (t_min, t_max).
bool intersect_scene(const Scene& scene, int t, const Ray& world_ray, double t_min, double t_max,
                     Hit* hit);

// True when the surface point `world` (at frame t) is seen by `camera`: in front of it, inside
// the image, and no surface crosses the segment from the camera centre to it before
// (1 - rel_tolerance) of its length. A point on the far side of a closed body is hidden by the
// body's near side (self occlusion) like any other occluder.
bool point_visible(const Scene& scene, int t, const Camera& camera, const Eigen::Vector3d& world,
                   double rel_tolerance = 1e-4);

struct RenderOptions {
  int supersample = 2;          // k: k x k colour rays per pixel (1 = pixel centre only)
  bool surface_points = false;  // also write RenderOutput::surface
  smg::ParallelOptions parallel;
};

struct RenderOutput {
  int width = 0, height = 0;
  Image rgb;                         // [H][W][3], mean colour of the k x k rays, [0, 1]
  std::vector<float> depth;          // [H][W], z in the camera at the pixel centre; 0 = no hit
  std::vector<std::int32_t> body;    // [H][W], body id at the pixel centre; -1 = no hit
  std::vector<float> surface;        // [H][W][3], hit point in the body frame (if requested)
};

// Renders `scene` at integer frame t through `camera` (image size from the camera). Rows run in
// parallel; every pixel is independent, so the output is the same for any thread count.
RenderOutput render(const Scene& scene, int t, const Camera& camera, const RenderOptions& options = {});

// Renders the training camera at every frame: [T] outputs.
std::vector<RenderOutput> render_training_view(const Scene& scene, const RenderOptions& options = {});
// Renders test camera `view` at every frame: [T] outputs.
std::vector<RenderOutput> render_test_view(const Scene& scene, int view, const RenderOptions& options = {});

// Co-visibility of a test view (the evaluation mask, as Dycheck's protocol uses): pixel (x, y) of
// test frame t is 1 when the surface point seen there was visible to the training camera in at
// least `min_frames` training frames (any time; moving points are followed by their analytic
// motion). Pixels that see nothing are 0. `test` must carry surface points. Returns [T][H][W].
std::vector<std::uint8_t> covisibility_mask(const Scene& scene, const std::vector<RenderOutput>& test,
                                            int min_frames = 1, smg::ParallelOptions parallel = {});

}  // namespace trainer
