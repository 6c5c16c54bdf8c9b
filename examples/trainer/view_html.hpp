// examples/trainer/view_html.hpp — OUT/view.html: one self-contained page of a run (docs/trainer.md,
// "view.html").
//
// The page shows the node graph over time in 3D (WebGL 2: orbit, zoom, pan), nodes coloured by
// their confidence c_t (E6) or by semantic class, the graph's edges (and those the semantic gate
// cut), trails, the Gaussian centres (subsampled), the cameras as frusta, the 3D query tracks
// (--track-queries), and per frame the training image, the render and each validation view with
// its covisible mask and PSNR; its header holds the run's metrics.json line (settings, graph
// statistics, timings, metrics). The page's JS and CSS (examples/trainer/view/) are compiled into
// the program; the run's data is embedded as one base64 block, quantised:
//   * positions (nodes, Gaussian centres, query tracks): uint16 per axis against the box
//     [lo, hi] of all of them, x = lo + q (hi − lo) / 65535, so the error per axis is at most
//     (hi − lo) / 131070 (half a step);
//   * confidences: uint8, c = q / 255 (error ≤ 1/510);
//   * images: JPEG (quality 85), covisible masks PNG.
// Nothing is fetched when the page is opened: it works from file:// offline.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "trainer/pipeline.hpp"

namespace trainer {

// RFC 4648 base64 (standard alphabet, '=' padding, no line breaks) of `n` bytes.
std::string base64_encode(const std::uint8_t* data, std::size_t n);

// What view.html shows besides the run itself.
struct ViewInputs {
  std::string metrics_json;                  // the run's metrics.json line (shown in the header)
  const std::vector<float>* tracks = nullptr;  // --track-queries: [M][T][3] query tracks
  const std::vector<float>* truth = nullptr;   // --track-truth: [M][T][3], the error is coloured
  int queries = 0;                             // M
  int max_gaussians = 50000;                   // Gaussian centres drawn per frame, at most
};

// Writes OUT/view.html and OUT/view_nodes.npy (float32 [T][N][3], the node positions the page
// embeds before quantisation: what a test compares the page's decoded positions against).
// Returns view.html's path. Throws std::runtime_error when a file cannot be written.
std::string write_view_html(const std::string& out_dir, const TrainerResult& result, const ViewInputs& inputs);

}  // namespace trainer
