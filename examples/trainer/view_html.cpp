// examples/trainer/view_html.cpp — OUT/view.html (view_html.hpp). The page's JS, CSS and HTML
// come from examples/trainer/view/, compiled in as raw string literals (view_assets.hpp, made by
// CMake from those files).
#include "trainer/view_html.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "json_line.hpp"
#include "npy.hpp"
#include "smg/skin.hpp"
#include "trainer/image_io.hpp"
#include "trainer/metrics.hpp"
#include "trainer/util.hpp"
#include "view_assets.hpp"

namespace trainer {

std::string base64_encode(const std::uint8_t* data, std::size_t n) {
  static const char* const alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((n + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= n; i += 3) {
    const std::uint32_t v = (std::uint32_t{data[i]} << 16) | (std::uint32_t{data[i + 1]} << 8) | data[i + 2];
    for (int s = 18; s >= 0; s -= 6) out += alphabet[(v >> s) & 63U];
  }
  if (i < n) {  // one or two bytes left: two or three symbols and the padding
    const std::uint32_t v = (std::uint32_t{data[i]} << 16) | (i + 1 < n ? std::uint32_t{data[i + 1]} << 8 : 0U);
    out += alphabet[(v >> 18) & 63U];
    out += alphabet[(v >> 12) & 63U];
    out += i + 1 < n ? alphabet[(v >> 6) & 63U] : '=';
    out += '=';
  }
  return out;
}

namespace {

namespace fs = std::filesystem;

// The page's binary block: arrays appended one after the other (each starting on a 4-byte
// boundary so that the page can view it as a typed array) and a JSON index of them.
class ViewBlob {
 public:
  // Appends `count` values of T under `name` with the given shape; `extra` is more JSON members
  // (",\"key\":value...") of the index entry.
  template <class T>
  void add(const std::string& name, const T* data, std::size_t count, const std::vector<long long>& shape,
           const std::string& type, const std::string& extra = "") {
    while (bytes_.size() % 4 != 0) bytes_.push_back(0);
    const std::size_t offset = bytes_.size();
    const auto* p = reinterpret_cast<const std::uint8_t*>(data);
    bytes_.insert(bytes_.end(), p, p + count * sizeof(T));
    std::string dims;
    for (long long d : shape) dims += (dims.empty() ? "" : ",") + std::to_string(d);
    index_ += (index_.empty() ? "" : ",") + cli::JsonLine::quote(name) + ":{\"type\":\"" + type +
              "\",\"offset\":" + std::to_string(offset) + ",\"bytes\":" + std::to_string(count * sizeof(T)) +
              ",\"shape\":[" + dims + "]" + extra + "}";
  }
  void add_bytes(const std::string& name, const std::vector<std::uint8_t>& b, const std::string& mime) {
    add(name, b.data(), b.size(), {static_cast<long long>(b.size())}, "u8", ",\"mime\":\"" + mime + "\"");
  }
  const std::vector<std::uint8_t>& bytes() const { return bytes_; }
  std::string index() const { return "{" + index_ + "}"; }

 private:
  std::vector<std::uint8_t> bytes_;
  std::string index_;
};

// The box every embedded position is quantised against (view_html.hpp): lo and the step per axis.
struct ViewQuantiser {
  std::array<double, 3> lo{}, step{};
  std::uint16_t q(double x, int axis) const {
    const double v = std::round((x - lo[sz(axis)]) / step[sz(axis)]);
    return static_cast<std::uint16_t>(std::clamp(v, 0.0, 65535.0));
  }
  std::string json() const {
    char b[256];
    std::snprintf(b, sizeof b, "{\"lo\":[%.9g,%.9g,%.9g],\"step\":[%.9g,%.9g,%.9g]}", lo[0], lo[1], lo[2], step[0],
                  step[1], step[2]);
    return b;
  }
};

template <class S>
void view_extend_box(const std::vector<S>& xyz, std::array<double, 3>& lo, std::array<double, 3>& hi) {
  for (std::size_t i = 0; i + 2 < xyz.size(); i += 3)
    for (std::size_t a = 0; a < 3; ++a) {
      const double v = static_cast<double>(xyz[i + a]);
      if (!std::isfinite(v)) continue;
      lo[a] = std::min(lo[a], v);
      hi[a] = std::max(hi[a], v);
    }
}

template <class S>
std::vector<std::uint16_t> view_quantise(const std::vector<S>& xyz, const ViewQuantiser& qz) {
  std::vector<std::uint16_t> q(xyz.size());
  for (std::size_t i = 0; i < xyz.size(); ++i) q[i] = qz.q(static_cast<double>(xyz[i]), static_cast<int>(i % 3));
  return q;
}

std::uint8_t view_unit_byte(double v) {
  return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0));
}

// A camera as the page draws it: centre, world-to-camera rotation (rows), intrinsics, size.
std::string view_camera_json(const Camera& c, const std::string& name) {
  const Eigen::Vector3d o = c.center();
  const Eigen::Matrix3d R = c.rotation();
  char b[512];  // numbers only: the name, of any length, is joined as a string
  std::snprintf(b, sizeof b,
                ",\"c\":[%.6g,%.6g,%.6g],\"R\":[%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g],"
                "\"f\":[%.6g,%.6g],\"pp\":[%.6g,%.6g],\"size\":[%d,%d]}",
                o.x(), o.y(), o.z(), R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2),
                c.fx, c.fy, c.cx, c.cy, c.width, c.height);
  return "{\"name\":" + cli::JsonLine::quote(name) + b;
}

// The Gaussian centres the page draws: up to `budget` rows; static ones once, dynamic ones posed
// at every frame (smg::skin_blend, as the renderer poses them).
struct ViewGaussians {
  std::vector<float> fixed;        // [S][3]
  std::vector<std::uint8_t> fixed_rgb;
  std::vector<float> moving;       // [T][D][3]
  std::vector<std::uint8_t> moving_rgb;
  int fixed_count = 0, moving_count = 0;
};

ViewGaussians view_gaussians(const TrainerResult& r, int budget) {
  ViewGaussians g;
  const GaussianModel<float>& m = r.model;
  const int F = m.fixed, P = m.dynamic(), T = r.nodes.frames, D = m.skin.width;
  // Dynamic centres cost T times the storage of static ones: at most 200k posed samples in all.
  const int moving_budget = std::min(P, std::max(1, std::min(budget / 2, 200000 / std::max(T, 1))));
  const int fixed_budget = std::min(F, std::max(0, budget - moving_budget));
  const auto rgb = [&](int row, std::vector<std::uint8_t>& out) {
    for (int a = 0; a < 3; ++a) out.push_back(view_unit_byte(m.table.colors[sz(row) * 3 + sz(a)]));
  };
  for (int k = 0; k < fixed_budget; ++k) {
    const int row = static_cast<int>(static_cast<long long>(k) * F / fixed_budget);
    for (int a = 0; a < 3; ++a) g.fixed.push_back(m.table.means[sz(row) * 3 + sz(a)]);
    rgb(row, g.fixed_rgb);
  }
  g.fixed_count = fixed_budget;
  if (P == 0 || T == 0 || moving_budget == 0) return g;
  // The chosen dynamic rows as a model of their own, posed as the renderer poses them.
  GaussianModel<float> sub;
  sub.skin.width = D;
  for (int k = 0; k < moving_budget; ++k) {
    const int p = static_cast<int>(static_cast<long long>(k) * P / moving_budget);
    const auto from = static_cast<long>(sz(p) * sz(D)), to = static_cast<long>(sz(p + 1) * sz(D));
    sub.table.push_row(m.table, F + p);
    sub.skin.drivers.insert(sub.skin.drivers.end(), m.skin.drivers.begin() + from, m.skin.drivers.begin() + to);
    sub.skin.weights.insert(sub.skin.weights.end(), m.skin.weights.begin() + from, m.skin.weights.begin() + to);
    sub.skin.t_ref.push_back(m.skin.t_ref[sz(p)]);
    rgb(F + p, g.moving_rgb);
  }
  const int n = moving_budget;
  const smg::SkinPoints<float> pts = skin_points(sub);
  NodeState<float> ns;
  ns.assign(r.nodes);
  std::vector<std::int32_t> frames(sz(T));
  for (int t = 0; t < T; ++t) frames[sz(t)] = t;
  g.moving.assign(sz(T) * sz(n) * 3, 0.0f);
  std::vector<float> posed_quats(sz(T) * sz(n) * 4, 0.0f);
  smg::SkinBlendOutputs<float> out;
  out.positions = smg::SequenceView<float, 3>(g.moving.data(), T, n);
  out.quaternions = smg::SequenceView<float, 4>(posed_quats.data(), T, n);
  const smg::SkinIndexView t_query(frames.data(), T);
  check(smg::validate_skin_blend(ns.skin_nodes(), pts, t_query, out), "view.html skin_blend");
  smg::skin_blend(ns.skin_nodes(), pts, t_query, out, smg::SkinOptions{});
  g.moving_count = n;
  return g;
}

// One picture of the images panel: frame, label, the JPEGs (truth, render) and mask, and a score.
struct ViewPicture {
  int frame = 0;
  std::string label, truth, render, mask;  // blob names ("" = none)
  double psnr = std::numeric_limits<double>::quiet_NaN();
  std::string score_name = "PSNR";
};

std::string view_pictures_json(const std::vector<ViewPicture>& pictures) {
  std::string s = "[";
  for (const ViewPicture& p : pictures) {
    cli::JsonLine j;
    j.add("frame", p.frame).add("label", p.label).add("truth", p.truth).add("render", p.render).add("mask", p.mask);
    if (std::isfinite(p.psnr)) j.add("score", p.psnr).add("score_name", p.score_name);
    s += (s.size() > 1 ? "," : "") + j.str();
  }
  return s + "]";
}

Image view_mask_image(const std::uint8_t* mask, int width, int height) {
  Image im(width, height, 1);
  for (std::size_t i = 0; i < im.pixels.size(); ++i) im.pixels[i] = mask[i] != 0 ? 1.0f : 0.0f;
  return im;
}

// The images panel: per frame the training image and render, and every validation view.
std::vector<ViewPicture> view_pictures(const TrainerResult& r, ViewBlob& blob) {
  std::vector<ViewPicture> pictures;
  const Dataset& d = r.data;
  const int T = r.nodes.frames;
  const auto jpeg = [&](const Image& im, const std::string& name) {
    if (im.empty()) return std::string();
    blob.add_bytes(name, encode_image(im, ImageCodec::jpeg, 85), "image/jpeg");
    return name;
  };
  const Evaluation& ev = r.evaluation;
  const bool train_renders = !ev.renders.empty() && sz(T) <= ev.renders.back().size();
  for (int t = 0; t < T && sz(t) < d.images.size(); ++t) {
    ViewPicture p;
    p.frame = t;
    p.label = "training view";
    p.truth = jpeg(d.images[sz(t)], "train_truth_" + std::to_string(t));
    if (train_renders) {
      const Image& render = ev.renders.back()[sz(t)];
      p.render = jpeg(render, "train_render_" + std::to_string(t));
      p.psnr = psnr(render, d.images[sz(t)]);
    }
    pictures.push_back(p);
  }
  // Procedural test views: fixed cameras at every frame, scored on their covisible pixels (none
  // from disk: its truth is empty).
  {
    const GroundTruth& g = truth_or_empty(d);
    for (std::size_t v = 0; v < g.test.size() && v + 1 < ev.renders.size(); ++v)
      for (int t = 0; t < T && sz(t) < g.test[v].size(); ++t) {
        const std::string id = std::to_string(v) + "_" + std::to_string(t);
        const RenderOutput& truth = g.test[v][sz(t)];
        ViewPicture p;
        p.frame = t;
        p.label = v < g.scene.test_views.size() ? "test view " + g.scene.test_views[v].name : "test view";
        p.truth = jpeg(truth.rgb, "test_truth_" + id);
        p.render = jpeg(ev.renders[v][sz(t)], "test_render_" + id);
        const std::uint8_t* mask = nullptr;
        if (v < g.test_covisible.size() && !g.test_covisible[v].empty()) {
          mask = g.test_covisible[v].data() + sz(t) * sz(truth.width) * sz(truth.height);
          blob.add_bytes("test_mask_" + id,
                         encode_image(view_mask_image(mask, truth.width, truth.height), ImageCodec::png), "image/png");
          p.mask = "test_mask_" + id;
        }
        p.psnr = psnr(ev.renders[v][sz(t)], truth.rgb, mask);
        p.score_name = mask ? "mPSNR" : "PSNR";
        pictures.push_back(p);
      }
  }
  // A scene from disk: the validation frames, at the training frame they were rendered for.
  for (std::size_t v = 0; v < d.eval.size(); ++v) {
    const EvalFrame& e = d.eval[v];
    ViewPicture p;
    p.frame = e.frame;
    p.label = "validation " + e.name;
    p.truth = jpeg(e.rgb, "eval_truth_" + std::to_string(v));
    if (v < ev.frame_renders.size()) p.render = jpeg(ev.frame_renders[v], "eval_render_" + std::to_string(v));
    if (!e.covisible.empty()) {
      blob.add_bytes("eval_mask_" + std::to_string(v),
                     encode_image(view_mask_image(e.covisible.data(), e.rgb.width, e.rgb.height), ImageCodec::png),
                     "image/png");
      p.mask = "eval_mask_" + std::to_string(v);
    }
    if (v < ev.frames.size()) {
      p.psnr = ev.frames[v].mpsnr;
      p.score_name = "mPSNR";
    }
    pictures.push_back(p);
  }
  return pictures;
}

// Node classes: the ground-truth body's semantic class (procedural scene), else the largest
// component of the node's descriptor (a coarse grouping of the features the gate compares).
std::vector<std::uint8_t> view_node_classes(const TrainerResult& r, std::vector<std::string>* names) {
  const Nodes& n = r.nodes;
  std::vector<std::uint8_t> cls(sz(n.count), 255);
  const Scene& scene = truth_or_empty(r.data).scene;  // no classes from disk
  if (n.body.size() == sz(n.count) && !scene.class_names.empty()) {
    *names = scene.class_names;
    for (int i = 0; i < n.count; ++i) {
      const int b = n.body[sz(i)];
      if (b >= 0 && b < scene.body_count()) cls[sz(i)] = static_cast<std::uint8_t>(scene.bodies[sz(b)].semantic_class);
    }
    return cls;
  }
  const int C = n.feature_dim;
  if (C <= 0 || n.descriptors.size() != sz(n.count) * sz(C)) return cls;
  const int classes = std::min(C, 255);
  for (int c = 0; c < classes; ++c) names->push_back("feature " + std::to_string(c));
  for (int i = 0; i < n.count; ++i) {
    const double* x = n.descriptors.data() + sz(i) * sz(C);
    cls[sz(i)] = static_cast<std::uint8_t>(std::max_element(x, x + classes) - x);
  }
  return cls;
}

// Edges an ungated KNN graph has and the variant's gated one lacks: those the semantic gate cut.
std::vector<std::uint16_t> view_cut_edges(const TrainerResult& r) {
  std::vector<std::uint16_t> cut;
  if (!r.config.variant.semantic_graph || r.nodes.count > 65535) return cut;
  Nodes ungated = r.nodes;
  build_graph(ungated, r.config.nodes, /*semantic=*/false);
  const NodeGraph& g = r.nodes.graph;
  const NodeGraph& u = ungated.graph;
  const auto has = [](const NodeGraph& graph, int i, int j) {
    for (int k = 0; k < graph.k; ++k)
      if (graph.indices[sz(i) * sz(graph.k) + sz(k)] == j) return true;
    return false;
  };
  for (int i = 0; i < u.nodes; ++i)
    for (int k = 0; k < u.k; ++k) {
      const int j = u.indices[sz(i) * sz(u.k) + sz(k)];
      if (j < 0 || has(g, i, j) || has(g, j, i)) continue;
      if (j < i && has(u, j, i)) continue;  // listed from j's side already
      cut.push_back(static_cast<std::uint16_t>(i));
      cut.push_back(static_cast<std::uint16_t>(j));
    }
  return cut;
}

// Replaces the one occurrence of `key` in `page`.
void view_fill(std::string& page, const std::string& key, const std::string& value) {
  const std::size_t at = page.find(key);
  if (at == std::string::npos) throw std::logic_error("view.html template lacks " + key);
  page.replace(at, key.size(), value);
}

// JSON text that is safe inside a <script> element ("</" would end it).
std::string view_script_safe(std::string json) {
  for (std::size_t at = 0; (at = json.find("</", at)) != std::string::npos; at += 3) json.replace(at, 2, "<\\/");
  return json;
}

}  // namespace

std::string write_view_html(const std::string& out_dir, const TrainerResult& r, const ViewInputs& in) {
  const Nodes& n = r.nodes;
  const int T = n.frames, N = n.count;
  if (N > 65535) throw std::runtime_error("view.html: more than 65535 nodes");
  ViewBlob blob;

  // Positions share one quantisation box.
  const ViewGaussians gs = view_gaussians(r, in.max_gaussians);
  std::array<double, 3> lo{}, hi{};
  lo.fill(std::numeric_limits<double>::infinity());
  hi.fill(-std::numeric_limits<double>::infinity());
  view_extend_box(n.positions, lo, hi);
  view_extend_box(gs.fixed, lo, hi);
  view_extend_box(gs.moving, lo, hi);
  const bool tracks = in.tracks && in.queries > 0 && in.tracks->size() == sz(in.queries) * sz(T) * 3;
  if (tracks) view_extend_box(*in.tracks, lo, hi);
  ViewQuantiser qz;
  for (std::size_t a = 0; a < 3; ++a) {
    if (!(lo[a] <= hi[a])) lo[a] = hi[a] = 0;
    qz.lo[a] = lo[a];
    qz.step[a] = std::max(hi[a] - lo[a], 1e-9) / 65535.0;
  }

  const std::vector<std::uint16_t> qnodes = view_quantise(n.positions, qz);
  blob.add("nodes", qnodes.data(), qnodes.size(), {T, N, 3}, "u16");
  // Confidences c_t (E6) of the final trajectories, whatever the variant used.
  const std::vector<double> c = node_confidences(n, n.positions, r.config.node_loss.regularizers.confidence, {},
                                                 r.config.node_loss.confidence_visibility);
  std::vector<std::uint8_t> qc(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) qc[i] = view_unit_byte(c[i]);
  blob.add("confidence", qc.data(), qc.size(), {T, N}, "u8");
  blob.add("visible", n.visible.data(), n.visible.size(), {T, N}, "u8");
  std::vector<std::string> class_names;
  const std::vector<std::uint8_t> cls = view_node_classes(r, &class_names);
  blob.add("classes", cls.data(), cls.size(), {N}, "u8");
  std::vector<std::uint16_t> graph(n.graph.indices.size());
  for (std::size_t i = 0; i < graph.size(); ++i)
    graph[i] = n.graph.indices[i] < 0 ? 65535 : static_cast<std::uint16_t>(n.graph.indices[i]);
  blob.add("graph", graph.data(), graph.size(), {N, n.graph.k}, "u16");
  const std::vector<std::uint16_t> cut = view_cut_edges(r);
  blob.add("cut_edges", cut.data(), cut.size(), {static_cast<long long>(cut.size() / 2), 2}, "u16");
  if (gs.fixed_count > 0) {
    const std::vector<std::uint16_t> q = view_quantise(gs.fixed, qz);
    blob.add("gaussians_static", q.data(), q.size(), {gs.fixed_count, 3}, "u16");
    blob.add("gaussians_static_rgb", gs.fixed_rgb.data(), gs.fixed_rgb.size(), {gs.fixed_count, 3}, "u8");
  }
  if (gs.moving_count > 0) {
    const std::vector<std::uint16_t> q = view_quantise(gs.moving, qz);
    blob.add("gaussians_dynamic", q.data(), q.size(), {T, gs.moving_count, 3}, "u16");
    blob.add("gaussians_dynamic_rgb", gs.moving_rgb.data(), gs.moving_rgb.size(), {gs.moving_count, 3}, "u8");
  }
  if (tracks) {
    const std::vector<std::uint16_t> q = view_quantise(*in.tracks, qz);
    blob.add("queries", q.data(), q.size(), {in.queries, T, 3}, "u16");
    if (in.truth && in.truth->size() == in.tracks->size()) {
      std::vector<float> err(sz(in.queries) * sz(T));
      for (std::size_t k = 0; k < err.size(); ++k) {
        const float dx = (*in.tracks)[k * 3] - (*in.truth)[k * 3], dy = (*in.tracks)[k * 3 + 1] - (*in.truth)[k * 3 + 1],
                    dz = (*in.tracks)[k * 3 + 2] - (*in.truth)[k * 3 + 2];
        err[k] = std::sqrt(dx * dx + dy * dy + dz * dz);
      }
      blob.add("query_error", err.data(), err.size(), {in.queries, T}, "f32");
    }
  }
  const std::vector<ViewPicture> pictures = view_pictures(r, blob);

  // Cameras: the training camera at every frame, and the test / validation cameras.
  std::string train_cams = "[", test_cams = "[";
  for (std::size_t t = 0; t < r.data.cameras.size(); ++t)
    train_cams += (t ? "," : "") + view_camera_json(r.data.cameras[t], "train " + std::to_string(t));
  {
    const Scene& scene = truth_or_empty(r.data).scene;  // no test cameras from disk
    for (std::size_t v = 0; v < scene.test_cameras.size(); ++v)
      test_cams += (v ? "," : "") + view_camera_json(scene.test_cameras[v], v < scene.test_views.size()
                                                                                  ? "test " + scene.test_views[v].name
                                                                                  : "test");
  }
  for (std::size_t v = 0; v < r.data.eval.size(); ++v)
    test_cams += (test_cams.size() > 1 ? "," : "") + view_camera_json(r.data.eval[v].camera, r.data.eval[v].name);
  std::string names = "[";
  for (const std::string& s : class_names) names += (names.size() > 1 ? "," : "") + cli::JsonLine::quote(s);

  cli::JsonLine head;
  head.add("format", 1)
      .add("T", T)
      .add("N", N)
      .add("K", n.graph.k)
      .add("extent", r.data.extent)
      .add("unit", n.unit)
      .add("source", r.data.source)
      .add("variant", to_string(r.config.variant.variant))
      .add("semantic_graph", r.config.variant.semantic_graph)
      .add("has_truth", r.data.truth.has_value())
      .add_raw("quant", qz.json())
      .add_raw("class_names", names + "]")
      .add_raw("train_cameras", train_cams + "]")
      .add_raw("test_cameras", test_cams + "]")
      .add_raw("pictures", view_pictures_json(pictures))
      .add_raw("arrays", blob.index())
      .add_raw("metrics", in.metrics_json.empty() ? "{}" : in.metrics_json);

  std::string page = view_assets::html;
  view_fill(page, "/*SMG_VIEW_CSS*/", view_assets::css);
  view_fill(page, "/*SMG_VIEW_HEADER*/", view_script_safe(head.str()));
  view_fill(page, "@SMG_VIEW_DATA@", base64_encode(blob.bytes().data(), blob.bytes().size()));
  view_fill(page, "/*SMG_VIEW_JS*/", view_assets::js);

  const fs::path path = fs::path(out_dir) / "view.html";
  std::ofstream f(path, std::ios::binary);
  f << page;
  if (!f) throw std::runtime_error("cannot write " + path.string());
  const std::vector<float> positions(n.positions.begin(), n.positions.end());
  npy::write((fs::path(out_dir) / "view_nodes.npy").string(), positions.data(), {T, N, 3});
  return path.string();
}

}  // namespace trainer
