// examples/trainer/image_io.cpp — PNG writing (stb_image_write) and picture helpers.
//
// This is the one translation unit that compiles stb_image_write's implementation.
#include "trainer/image_io.hpp"

#if !__has_include(<stb/stb_image_write.h>)
#error "the example trainer needs stb_image_write.h (Debian: apt-get install libstb-dev)"
#endif

#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>
#include <stb/stb_easy_font.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include <Eigen/Eigenvalues>

#include "trainer/random.hpp"

namespace trainer {

namespace {

Image to_channels(const Image& im, int channels) {
  if (im.channels == channels) return im;
  if (!(im.channels == 1 && channels == 3))
    throw std::invalid_argument("image_io: cannot combine images with " + std::to_string(im.channels) + " and " +
                                std::to_string(channels) + " channels");
  Image out(im.width, im.height, 3);
  for (std::size_t i = 0; i < static_cast<std::size_t>(im.width) * im.height; ++i)
    for (int c = 0; c < 3; ++c) out.pixels[i * 3 + c] = im.pixels[i];
  return out;
}

int common_channels(const std::vector<Image>& parts) {
  int c = 0;
  for (const Image& p : parts) c = std::max(c, p.channels);
  return c;
}

void blit(Image& dst, const Image& src, int x0, int y0) {
  for (int y = 0; y < src.height; ++y)
    for (int x = 0; x < src.width; ++x)
      for (int c = 0; c < dst.channels; ++c) dst.at(x0 + x, y0 + y, c) = src.at(x, y, c);
}

void put(Image& im, int x, int y, const Eigen::Vector3f& color) {
  if (x < 0 || y < 0 || x >= im.width || y >= im.height) return;
  for (int c = 0; c < std::min(3, im.channels); ++c) im.at(x, y, c) = color(c);
}

// Polynomial fit of Google's Turbo colour map (Mikhailov 2019), t in [0, 1].
Eigen::Vector3f turbo(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const double r = 0.13572138 + t * (4.61539260 + t * (-42.66032258 + t * (132.13108234 + t * (-152.94239396 + t * 59.28637943))));
  const double g = 0.09140261 + t * (2.19418839 + t * (4.84296658 + t * (-14.18503333 + t * (4.27729857 + t * 2.82956604))));
  const double b = 0.10667330 + t * (12.64194608 + t * (-60.58204836 + t * (110.36276771 + t * (-89.90310912 + t * 27.34824973))));
  return Eigen::Vector3f(static_cast<float>(std::clamp(r, 0.0, 1.0)), static_cast<float>(std::clamp(g, 0.0, 1.0)),
                         static_cast<float>(std::clamp(b, 0.0, 1.0)));
}

}  // namespace

namespace {
// The image's pixels as 8-bit values (clamped to [0, 1] and rounded), for stb_image_write.
std::vector<unsigned char> image_bytes(const Image& image) {
  std::vector<unsigned char> bytes(image.pixels.size());
  for (std::size_t i = 0; i < bytes.size(); ++i)
    bytes[i] = static_cast<unsigned char>(std::lround(std::clamp(image.pixels[i], 0.0f, 1.0f) * 255.0f));
  return bytes;
}

// stb_image_write's callback: appends the encoded bytes to a std::vector<std::uint8_t>.
void append_encoded_bytes(void* context, void* data, int size) {
  auto* out = static_cast<std::vector<std::uint8_t>*>(context);
  const auto* p = static_cast<const std::uint8_t*>(data);
  out->insert(out->end(), p, p + size);
}
}  // namespace

void write_png(const std::string& path, const Image& image) {
  if (image.empty() || image.channels < 1 || image.channels > 4)
    throw std::runtime_error("cannot write PNG '" + path + "': empty image or bad channel count");
  const std::vector<unsigned char> bytes = image_bytes(image);
  if (!stbi_write_png(path.c_str(), image.width, image.height, image.channels, bytes.data(),
                      image.width * image.channels))
    throw std::runtime_error("cannot write PNG '" + path + "'");
}

std::vector<std::uint8_t> encode_image(const Image& image, ImageCodec codec, int jpeg_quality) {
  if (image.empty() || image.channels < 1 || image.channels > 4)
    throw std::runtime_error("cannot encode an empty image or one with a bad channel count");
  const std::vector<unsigned char> bytes = image_bytes(image);
  std::vector<std::uint8_t> out;
  const int ok = codec == ImageCodec::png
                     ? stbi_write_png_to_func(append_encoded_bytes, &out, image.width, image.height, image.channels,
                                              bytes.data(), image.width * image.channels)
                     : stbi_write_jpg_to_func(append_encoded_bytes, &out, image.width, image.height, image.channels,
                                              bytes.data(), jpeg_quality);
  if (!ok) throw std::runtime_error("cannot encode an image");
  return out;
}

namespace {
// hstack (horizontal) and vstack: the parts one after the other, `gap` pixels of gap_value between.
Image stack(const std::vector<Image>& parts, int gap, float gap_value, bool horizontal) {
  if (parts.empty()) return {};
  const int C = common_channels(parts);
  int along = 0, across = 0;
  for (const Image& p : parts) {
    along += horizontal ? p.width : p.height;
    across = std::max(across, horizontal ? p.height : p.width);
  }
  along += gap * static_cast<int>(parts.size() - 1);
  Image out(horizontal ? along : across, horizontal ? across : along, C, gap_value);
  int at = 0;
  for (const Image& p : parts) {
    blit(out, to_channels(p, C), horizontal ? at : 0, horizontal ? 0 : at);
    at += (horizontal ? p.width : p.height) + gap;
  }
  return out;
}
}  // namespace

Image hstack(const std::vector<Image>& parts, int gap, float gap_value) { return stack(parts, gap, gap_value, true); }

Image vstack(const std::vector<Image>& parts, int gap, float gap_value) { return stack(parts, gap, gap_value, false); }

Image grid(const std::vector<Image>& cells, int columns, int gap, float gap_value) {
  if (cells.empty()) return {};
  if (columns < 1) throw std::invalid_argument("grid: columns must be >= 1");
  std::vector<Image> rows;
  for (std::size_t i = 0; i < cells.size(); i += static_cast<std::size_t>(columns)) {
    std::vector<Image> row(cells.begin() + static_cast<std::ptrdiff_t>(i),
                           cells.begin() + static_cast<std::ptrdiff_t>(std::min(cells.size(), i + columns)));
    rows.push_back(hstack(row, gap, gap_value));
  }
  return vstack(rows, gap, gap_value);
}

Image upscale(const Image& im, int f) {
  if (f < 1) throw std::invalid_argument("upscale: factor must be >= 1");
  Image out(im.width * f, im.height * f, im.channels);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x)
      for (int c = 0; c < im.channels; ++c) out.at(x, y, c) = im.at(x / f, y / f, c);
  return out;
}

Image colorize_depth(const float* depth, int W, int H, double near, double far) {
  Image out(W, H, 3);
  const double span = far > near ? far - near : 1.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const double d = depth[static_cast<std::size_t>(y) * W + x];
      if (d > 0) put(out, x, y, turbo((d - near) / span));
    }
  return out;
}

FeatureProjection fit_feature_projection(const float* f, std::size_t count, int dim, std::size_t max_samples) {
  if (count == 0 || dim < 1) throw std::invalid_argument("fit_feature_projection: no features");
  const std::size_t stride = std::max<std::size_t>(1, count / std::max<std::size_t>(1, max_samples));
  std::vector<std::size_t> rows;
  for (std::size_t i = 0; i < count; i += stride) rows.push_back(i);
  Eigen::MatrixXd X(static_cast<Eigen::Index>(rows.size()), dim);
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (int k = 0; k < dim; ++k) X(static_cast<Eigen::Index>(r), k) = f[rows[r] * dim + k];
  FeatureProjection p;
  p.mean = X.colwise().mean().transpose();
  X.rowwise() -= p.mean.transpose();
  const Eigen::MatrixXd cov = X.transpose() * X / static_cast<double>(X.rows());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(cov);
  p.basis = Eigen::MatrixXd::Zero(3, dim);
  for (int k = 0; k < std::min(3, dim); ++k) {
    Eigen::VectorXd v = es.eigenvectors().col(dim - 1 - k);  // eigenvalues ascend
    Eigen::Index arg;
    v.cwiseAbs().maxCoeff(&arg);
    if (v(arg) < 0) v = -v;
    p.basis.row(k) = v.transpose();
  }
  const Eigen::MatrixXd Y = X * p.basis.transpose();  // rows x 3
  for (int k = 0; k < 3; ++k) {
    std::vector<double> col(static_cast<std::size_t>(Y.rows()));
    for (Eigen::Index r = 0; r < Y.rows(); ++r) col[static_cast<std::size_t>(r)] = Y(r, k);
    std::sort(col.begin(), col.end());
    p.lo(k) = col[col.size() / 100];
    p.hi(k) = col[col.size() - 1 - col.size() / 100];
    if (!(p.hi(k) > p.lo(k))) p.hi(k) = p.lo(k) + 1.0;
  }
  return p;
}

Image colorize_features(const float* f, int W, int H, int dim, const FeatureProjection& p) {
  if (p.basis.cols() != dim) throw std::invalid_argument("colorize_features: projection fitted to another dimension");
  Image out(W, H, 3);
  Eigen::VectorXd v(dim);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float* q = f + (static_cast<std::size_t>(y) * W + x) * dim;
      for (int k = 0; k < dim; ++k) v(k) = q[k];
      const Eigen::Vector3d c = p.basis * (v - p.mean);
      for (int k = 0; k < 3; ++k)
        out.at(x, y, k) = static_cast<float>(std::clamp((c(k) - p.lo(k)) / (p.hi(k) - p.lo(k)), 0.0, 1.0));
    }
  return out;
}

Eigen::Vector3f palette_color(std::uint64_t key) {
  // A hashed hue, full saturation, lifted towards white so it reads on dark backgrounds.
  const double h = unit_from_bits(mix64(key)) * 6.0;
  const double x = 1.0 - std::abs(std::fmod(h, 2.0) - 1.0);
  Eigen::Vector3d rgb;
  switch (static_cast<int>(h)) {
    case 0: rgb = {1, x, 0}; break;
    case 1: rgb = {x, 1, 0}; break;
    case 2: rgb = {0, 1, x}; break;
    case 3: rgb = {0, x, 1}; break;
    case 4: rgb = {x, 0, 1}; break;
    default: rgb = {1, 0, x}; break;
  }
  return (0.25 + 0.75 * rgb.array()).matrix().cast<float>();
}

Image colorize_labels(const std::int32_t* ids, int W, int H) {
  Image out(W, H, 3);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::int32_t id = ids[static_cast<std::size_t>(y) * W + x];
      if (id >= 0) put(out, x, y, palette_color(static_cast<std::uint64_t>(id) * 7919u + 3u));
    }
  return out;
}

void draw_disc(Image& im, double cx, double cy, double radius, const Eigen::Vector3f& color) {
  const int x0 = static_cast<int>(std::floor(cx - radius)), x1 = static_cast<int>(std::ceil(cx + radius));
  const int y0 = static_cast<int>(std::floor(cy - radius)), y1 = static_cast<int>(std::ceil(cy + radius));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
      if (dx * dx + dy * dy <= radius * radius) put(im, x, y, color);
    }
}

void draw_line(Image& im, double x0, double y0, double x1, double y1, const Eigen::Vector3f& color) {
  const double len = std::max(std::abs(x1 - x0), std::abs(y1 - y0));
  const int n = std::max(1, static_cast<int>(std::ceil(len)));
  if (n > 100000) return;  // a wild outlier; nothing sensible to draw
  for (int k = 0; k <= n; ++k) {
    const double a = static_cast<double>(k) / n;
    put(im, static_cast<int>(std::floor(x0 + a * (x1 - x0))), static_cast<int>(std::floor(y0 + a * (y1 - y0))), color);
  }
}

void draw_text(Image& im, int x, int y, const std::string& text, const Eigen::Vector3f& color, int scale) {
  if (text.empty() || scale < 1) return;
  std::string s = text;
  for (char& c : s)
    if (c != '\n' && (c < 32 || c > 126)) c = '?';
  std::vector<char> buffer(64 * (s.size() * 32 + 1));  // generous: <= ~30 quads per glyph
  const int quads = stb_easy_font_print(0, 0, s.data(), nullptr, buffer.data(), static_cast<int>(buffer.size()));
  const int tw = stb_easy_font_width(s.data()), th = stb_easy_font_height(s.data());
  // Backdrop one pixel larger than the text.
  for (int yy = y - scale; yy < y + (th + 1) * scale; ++yy)
    for (int xx = x - scale; xx < x + (tw + 1) * scale; ++xx)
      if (xx >= 0 && yy >= 0 && xx < im.width && yy < im.height)
        for (int c = 0; c < std::min(3, im.channels); ++c) im.at(xx, yy, c) *= 0.35f;
  for (int q = 0; q < quads; ++q) {
    // Vertices are 16 bytes (x, y, z floats + RGBA); a quad's opposite corners are 0 and 2.
    float v0[2], v2[2];
    std::memcpy(v0, buffer.data() + q * 64, sizeof v0);
    std::memcpy(v2, buffer.data() + q * 64 + 32, sizeof v2);
    const int qx0 = static_cast<int>(std::lround(v0[0])), qy0 = static_cast<int>(std::lround(v0[1]));
    const int qx1 = static_cast<int>(std::lround(v2[0])), qy1 = static_cast<int>(std::lround(v2[1]));
    for (int yy = std::min(qy0, qy1) * scale; yy < std::max(qy0, qy1) * scale; ++yy)
      for (int xx = std::min(qx0, qx1) * scale; xx < std::max(qx0, qx1) * scale; ++xx) put(im, x + xx, y + yy, color);
  }
}

void draw_tracks(Image& im, const double* uv, const std::uint8_t* visible, int frames, int count, int t, int trail,
                 int stride) {
  if (t < 0 || t >= frames || stride < 1) return;
  for (int i = 0; i < count; i += stride) {
    const Eigen::Vector3f color = palette_color(static_cast<std::uint64_t>(i));
    int prev = -1;
    for (int f = std::max(0, t - trail); f <= t; ++f) {
      const std::size_t s = static_cast<std::size_t>(f) * count + i;
      if (!visible[s]) {
        prev = -1;
        continue;
      }
      if (prev >= 0) {
        const std::size_t p = static_cast<std::size_t>(prev) * count + i;
        draw_line(im, uv[p * 2], uv[p * 2 + 1], uv[s * 2], uv[s * 2 + 1], 0.8f * color);
      }
      prev = f;
    }
    const std::size_t s = static_cast<std::size_t>(t) * count + i;
    if (visible[s]) draw_disc(im, uv[s * 2], uv[s * 2 + 1], 1.3, color);
  }
}

}  // namespace trainer
