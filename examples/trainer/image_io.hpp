// examples/trainer/image_io.hpp — PNG output and pictures a person can look at.
//
// PNGs are written with stb_image_write (Debian's libstb-dev): one small, widely used,
// well-kept public-domain header with no dependencies of its own, packaged by Debian, so the
// example needs no image library and nothing is downloaded. Only the writer is used (8-bit PNG; JPEG for view.html).
//
// Helpers build the example's pictures: strips (ground truth | render), contact sheets (a grid
// over time), colour-mapped depth, semantic features projected to RGB by PCA, track overlays
// and small text labels (stb_easy_font).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "trainer/image.hpp"

namespace trainer {

// Writes an 8-bit PNG (1, 2, 3 or 4 channels; values clamped to [0, 1] and rounded). Throws
// std::runtime_error naming the path when it cannot be written.
void write_png(const std::string& path, const Image& image);

// The same image encoded in memory: PNG (lossless) or baseline JPEG at `jpeg_quality` (1..100;
// 1 or 3 channels), e.g. for embedding in a page (view_html.hpp). Throws std::runtime_error.
enum class ImageCodec { png, jpeg };
std::vector<std::uint8_t> encode_image(const Image& image, ImageCodec codec, int jpeg_quality = 85);

// Side by side, top aligned, separated by `gap` pixels of `gap_value`. One-channel parts are
// expanded to three channels when any part has three.
Image hstack(const std::vector<Image>& parts, int gap = 2, float gap_value = 1.0f);
// Stacked vertically, left aligned.
Image vstack(const std::vector<Image>& parts, int gap = 2, float gap_value = 1.0f);
// A contact sheet: cells left to right, top to bottom, `columns` per row.
Image grid(const std::vector<Image>& cells, int columns, int gap = 2, float gap_value = 1.0f);
// Nearest-neighbour enlargement by an integer factor.
Image upscale(const Image& image, int factor);

// Depth [H][W] (0 = no depth) to RGB with the "turbo" colour map over [near, far]; no depth is
// black.
Image colorize_depth(const float* depth, int width, int height, double near, double far);

// A fixed linear map from C-dimensional features to RGB: the top three principal directions of
// a sample of features, each scaled to [0, 1] by its 1st and 99th percentile. Eigenvector signs
// are fixed (largest component positive) so the colours are reproducible.
struct FeatureProjection {
  Eigen::MatrixXd basis;   // 3 x C
  Eigen::VectorXd mean;    // C
  Eigen::Vector3d lo, hi;  // range of each projected component
};
// Fits the projection to `count` feature vectors of dimension `dim` (row-major), using at most
// `max_samples` of them (evenly strided).
FeatureProjection fit_feature_projection(const float* features, std::size_t count, int dim,
                                         std::size_t max_samples = 50000);
// Features [H][W][C] to RGB.
Image colorize_features(const float* features, int width, int height, int dim, const FeatureProjection& p);

// Label ids [H][W] (-1 = none, black) to distinct colours.
Image colorize_labels(const std::int32_t* ids, int width, int height);

// Drawing (clipped to the image; colours are RGB in [0, 1]).
void draw_disc(Image& image, double x, double y, double radius, const Eigen::Vector3f& color);
void draw_line(Image& image, double x0, double y0, double x1, double y1, const Eigen::Vector3f& color);
// Text with stb_easy_font (about 6 x 12 px per character at scale 1), on a dark backdrop so it
// reads on any image. Characters outside printable ASCII are drawn as '?'.
void draw_text(Image& image, int x, int y, const std::string& text, const Eigen::Vector3f& color,
               int scale = 1);

// A repeatable distinct colour for an integer (a track, a body).
Eigen::Vector3f palette_color(std::uint64_t key);

// Overlays tracks on `image` at frame t: for every track i (every `stride`-th), a trail through
// its reported positions in frames t-trail .. t where reported visible, and a dot at frame t.
// uv [T][N][2] pixels, visible [T][N].
void draw_tracks(Image& image, const double* uv, const std::uint8_t* visible, int frames, int count, int t,
                 int trail = 6, int stride = 1);

}  // namespace trainer
