// tests/cuda/core_cases.hpp — the cases of test_cuda_core.cu: one host-device evaluator that
// runs smg's device-callable core and splat maths on one packed input (the kernel calls it on
// the GPU, the test on the CPU: the same source on both sides), random and hard inputs, and the
// comparison of device against host outputs with per-quantity diagnostics.
//
// Plain C++ apart from SMG_HOST_DEVICE, so it also builds with a host compiler alone.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "smg/core/quaternion.hpp"
#include "smg/core/quaternion_manifold.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/so3.hpp"
#include "smg/splat/camera.hpp"
#include "smg/splat/projection.hpp"
#include "smg/splat/sh.hpp"

namespace smg_cuda_test {

// Packed sizes of one case: inputs and outputs (S values each).
constexpr int kIn = 64;
constexpr int kOut = 160;

enum Kind : int {
  kSo3Exp = 0,        // so3::exp with and without its Jacobian
  kSo3Log,            // so3::log with and without its Jacobian
  kSo3Jacobians,      // Jr, Jr^-1, Jl, hat, vee, the coefficient series
  kQuatProducts,      // compose, between, inverse, rotate, inverse_rotate, angular_distance
  kQuatMatrices,      // normalized, canonical, left/right product matrices, tangent Jacobian
  kManifold,          // quaternion_manifold plus/minus and their Jacobians
  kRotationGradient,  // add_quaternion_gradient_from_tangent, add_tangent_gradient_from_quaternion
  kProjection,        // splat::project_gaussian and project_gaussian_vjp
  kSh,                // splat::sh_basis, sh_to_color, sh_to_color_vjp
  kKindCount
};

inline const char* kind_name(int k) {
  static const char* const names[] = {"so3_exp",       "so3_log",           "so3_jacobians",
                                      "quat_products", "quat_matrices",     "manifold",
                                      "rotation_grad", "project_gaussian",  "sh"};
  return k >= 0 && k < kKindCount ? names[k] : "?";
}

// Projection inputs: viewmat [16] (row-major), fx fy cx cy width height near far, mean [3],
// quat [4], log_scale [3], eps2d, radius_sigmas, v_mean2d [2], v_conic [3], v_depth.
namespace proj {
constexpr int viewmat = 0, fx = 16, fy = 17, cx = 18, cy = 19, width = 20, height = 21,
              near_plane = 22, far_plane = 23, mean = 24, quat = 27, log_scale = 31, eps2d = 34,
              radius_sigmas = 35, v_mean2d = 36, v_conic = 38, v_depth = 41;
}  // namespace proj

template <class S>
SMG_HOST_DEVICE smg::splat::Camera<S> camera_from(const S* in) {
  smg::splat::Camera<S> cam;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) cam.viewmat(r, c) = in[proj::viewmat + 4 * r + c];
  cam.fx = in[proj::fx];
  cam.fy = in[proj::fy];
  cam.cx = in[proj::cx];
  cam.cy = in[proj::cy];
  cam.width = static_cast<int>(in[proj::width]);
  cam.height = static_cast<int>(in[proj::height]);
  cam.near_plane = in[proj::near_plane];
  cam.far_plane = in[proj::far_plane];
  return cam;
}

// Appends the coefficients of a matrix expression (column-major) to *o.
template <class S, class Derived>
SMG_HOST_DEVICE void put(S*& o, const Eigen::MatrixBase<Derived>& m) {
  for (Eigen::Index j = 0; j < m.cols(); ++j)
    for (Eigen::Index i = 0; i < m.rows(); ++i) *o++ = m(i, j);
}
template <class S>
SMG_HOST_DEVICE void put(S*& o, const smg::Quaternion<S>& q) {
  put(o, smg::to_wxyz(q));
}
template <class S>
SMG_HOST_DEVICE void put_scalar(S*& o, S v) {
  *o++ = v;
}

// Evaluates case `kind` on in[kIn] into out[kOut] (unused outputs are 0). The layout of the
// outputs is blocks(kind) below.
template <class S>
SMG_HOST_DEVICE void eval_case(int kind, const S* in, S* out) {
  using namespace smg;
  for (int k = 0; k < kOut; ++k) out[k] = S(0);
  S* o = out;
  const Vector3<S> v3(in[0], in[1], in[2]);
  switch (kind) {
    case kSo3Exp: {
      Matrix3<S> J;
      put(o, so3::exp(v3, &J));
      put(o, J);
      put(o, so3::exp(v3));
      break;
    }
    case kSo3Log: {
      const Quaternion<S> q = from_wxyz(in);
      Matrix3<S> J;
      put(o, so3::log(q, &J));
      put(o, J);
      put(o, so3::log(q));
      break;
    }
    case kSo3Jacobians: {
      const S t2 = v3.squaredNorm();
      put(o, so3::right_jacobian(v3));
      put(o, so3::right_jacobian_inverse(v3));
      put(o, so3::left_jacobian(v3));
      put(o, so3::hat(v3));
      put(o, so3::vee(so3::hat(v3)));
      put_scalar(o, so3::detail::coeff_b(t2));
      put_scalar(o, so3::detail::coeff_c(t2));
      put_scalar(o, so3::detail::coeff_d(t2));
      break;
    }
    case kQuatProducts: {
      const Quaternion<S> a = from_wxyz(in), b = from_wxyz(in + 4);
      const Vector3<S> v(in[8], in[9], in[10]);
      Matrix3<S> J1, J2;
      put(o, so3::compose(a, b, &J1, &J2));
      put(o, J1);
      put(o, J2);
      put(o, so3::between(a, b, &J1, &J2));
      put(o, J1);
      put(o, J2);
      put(o, so3::inverse(a, &J1));
      put(o, J1);
      put(o, so3::rotate(a, v, &J1, &J2));
      put(o, J1);
      put(o, J2);
      put(o, so3::inverse_rotate(a, v, &J1, &J2));
      put(o, J1);
      put(o, J2);
      put_scalar(o, so3::angular_distance(a, b));
      break;
    }
    case kQuatMatrices: {
      const Quaternion<S> q = from_wxyz(Vector4<S>(in[0], in[1], in[2], in[3]));
      Matrix4<S> J;
      put(o, normalized(q, &J));
      put(o, J);
      put(o, canonical(q));
      put(o, quat_left_matrix(q));
      put(o, quat_right_matrix(q));
      put(o, quat_tangent_jacobian(q));
      S wxyz[4];
      to_wxyz(q, wxyz);
      put(o, Vector4<S>(wxyz[0], wxyz[1], wxyz[2], wxyz[3]));
      break;
    }
    case kManifold: {
      namespace qm = quaternion_manifold;
      const S* q = in;          // [4]
      const S* delta = in + 4;  // [3]
      const S* y = in + 7;      // [4]
      S r[12];
      qm::plus(q, delta, r);
      put(o, Vector4<S>(r[0], r[1], r[2], r[3]));
      qm::minus(y, q, r);
      put(o, Vector3<S>(r[0], r[1], r[2]));
      qm::plus_jacobian(q, r);
      put(o, Eigen::Map<const Eigen::Matrix<S, 12, 1>>(r));
      qm::minus_jacobian(q, r);
      put(o, Eigen::Map<const Eigen::Matrix<S, 12, 1>>(r));
      put(o, qm::plus_jacobian(from_wxyz(q)));
      put(o, qm::minus_jacobian(from_wxyz(q)));
      const Eigen::Matrix<S, 2, 3> G = Eigen::Map<const Eigen::Matrix<S, 2, 3>>(in + 11);
      put(o, qm::ambient_jacobian(G, from_wxyz(q)));
      break;
    }
    case kRotationGradient: {
      const S* q = in;  // [4], not unit
      S g_q[4] = {in[11], in[12], in[13], in[14]};
      S g_phi[3] = {in[15], in[16], in[17]};
      add_quaternion_gradient_from_tangent(q, in + 4, g_q);     // g_phi input: in[4..6]
      add_tangent_gradient_from_quaternion(q, in + 7, g_phi);  // g_q input: in[7..10]
      put(o, Vector4<S>(g_q[0], g_q[1], g_q[2], g_q[3]));
      put(o, Vector3<S>(g_phi[0], g_phi[1], g_phi[2]));
      break;
    }
    case kProjection: {
      namespace sp = smg::splat;
      const sp::Camera<S> cam = camera_from(in);
      const Vector3<S> mean(in[proj::mean], in[proj::mean + 1], in[proj::mean + 2]);
      const Vector4<S> quat(in[proj::quat], in[proj::quat + 1], in[proj::quat + 2],
                            in[proj::quat + 3]);
      const Vector3<S> log_scale(in[proj::log_scale], in[proj::log_scale + 1],
                                 in[proj::log_scale + 2]);
      const S eps2d = in[proj::eps2d];
      sp::ProjectedGaussian<S> p;
      const sp::Cull c =
          sp::project_gaussian(cam, mean, quat, log_scale, eps2d, in[proj::radius_sigmas], &p);
      put_scalar(o, S(static_cast<int>(c)));
      if (c == sp::Cull::none) {
        put(o, p.mean2d);
        put(o, p.conic);
        put(o, p.cov2d);
        put_scalar(o, p.depth);
        put_scalar(o, p.radius);
        Vector3<S> v_mean, v_quat_tangent, v_log_scale;
        Vector4<S> v_quat;
        sp::project_gaussian_vjp(
            cam, mean, quat, log_scale, eps2d, p.conic,
            Vector2<S>(in[proj::v_mean2d], in[proj::v_mean2d + 1]),
            Vector3<S>(in[proj::v_conic], in[proj::v_conic + 1], in[proj::v_conic + 2]),
            in[proj::v_depth], &v_mean, &v_quat, &v_quat_tangent, &v_log_scale);
        put(o, v_mean);
        put(o, v_quat);
        put(o, v_quat_tangent);
        put(o, v_log_scale);
      } else {
        o += 24;  // the visible-only blocks stay 0
      }
      put(o, cam.center());
      put(o, sp::rotmat_from_unit_wxyz(Vector4<S>(quat / quat.norm())));
      break;
    }
    case kSh: {
      namespace sp = smg::splat;
      const int degree = static_cast<int>(in[0]);
      const Vector3<S> dir(in[1], in[2], in[3]);
      const S* coeffs = in + 4;      // [16][3]
      const S* v_color = in + 52;    // [3]
      S color[3], v_coeffs[48], Y[16], dY[48];
      for (int k = 0; k < 16; ++k) Y[k] = S(0);
      for (int k = 0; k < 48; ++k) dY[k] = v_coeffs[k] = S(0);
      sp::sh_to_color(degree, 3, dir, coeffs, color);
      const Vector3<S> v_dir = sp::sh_to_color_vjp(degree, 3, dir, coeffs, v_color, v_coeffs);
      const S n = dir.norm();
      sp::sh_basis(degree, n > S(0) ? Vector3<S>(dir / n) : Vector3<S>(S(1), S(0), S(0)), Y, dY);
      put(o, Vector3<S>(color[0], color[1], color[2]));
      put(o, Eigen::Map<const Eigen::Matrix<S, 48, 1>>(v_coeffs));
      put(o, v_dir);
      put(o, Eigen::Map<const Eigen::Matrix<S, 16, 1>>(Y));
      put(o, Eigen::Map<const Eigen::Matrix<S, 48, 1>>(dY));
      break;
    }
    default:
      break;
  }
}

// ---------------------------------------------------------------------------------------------
// Host side: output layout, cases, comparison.

// One compared quantity of a case's outputs. floor: the smallest scale the error is measured
// against (0: relative to the quantity itself; 1 or π: an absolute error, for quantities such
// as a rotation angle computed from a product of unit quaternions, or a coefficient function
// evaluated at a rounded argument, whose rounding error is absolute, not relative to a small
// result). conditioned: 1 for the conic, 2 for the gradients through it (projection only: the
// power of the 2D covariance's condition number in their rounding error, used for the
// near-singular cases; see compare()).
struct Block {
  const char* name;
  int size;
  double floor;
  int conditioned;
};

inline std::vector<Block> blocks(int kind) {
  const double pi = 3.14159265358979323846;
  switch (kind) {
    case kSo3Exp:
      return {{"exp(phi) wxyz", 4, 0, 0}, {"J_out_phi", 9, 0, 0},
              {"exp(phi) without J", 4, 0, 0}};
    case kSo3Log:
      return {{"log(q)", 3, 0, 0}, {"J_out_q", 9, 0, 0}, {"log(q) without J", 3, 0, 0}};
    case kSo3Jacobians:
      return {{"right_jacobian", 9, 0, 0}, {"right_jacobian_inverse", 9, 0, 0},
              {"left_jacobian", 9, 0, 0},  {"hat", 9, 0, 0},
              {"vee(hat)", 3, 0, 0},       {"coeff_b", 1, 0.5, 0},
              {"coeff_c", 1, 1.0 / 6, 0},        {"coeff_d", 1, 1.0 / 12, 0}};
    case kQuatProducts:
      return {{"compose", 4, 0, 0},        {"compose J_a", 9, 0, 0},
              {"compose J_b", 9, 0, 0},    {"between", 4, 0, 0},
              {"between J_a", 9, 0, 0},    {"between J_b", 9, 0, 0},
              {"inverse", 4, 0, 0},        {"inverse J", 9, 0, 0},
              {"rotate", 3, 0, 0},         {"rotate J_q", 9, 0, 0},
              {"rotate J_v", 9, 0, 0},     {"inverse_rotate", 3, 0, 0},
              {"inverse_rotate J_q", 9, 0, 0}, {"inverse_rotate J_v", 9, 0, 0},
              {"angular_distance", 1, pi, 0}};
    case kQuatMatrices:
      return {{"normalized", 4, 0, 0},       {"normalized J", 16, 0, 0},
              {"canonical", 4, 0, 0},        {"quat_left_matrix", 16, 0, 0},
              {"quat_right_matrix", 16, 0, 0}, {"quat_tangent_jacobian", 12, 0, 0},
              {"to_wxyz(ptr)", 4, 0, 0}};
    case kManifold:
      return {{"plus", 4, 0, 0},
              {"minus", 3, 1, 0},
              {"plus_jacobian(ptr)", 12, 0, 0},
              {"minus_jacobian(ptr)", 12, 0, 0},
              {"plus_jacobian(q)", 12, 0, 0},
              {"minus_jacobian(q)", 12, 0, 0},
              {"ambient_jacobian", 8, 0, 0}};
    case kRotationGradient:
      return {{"g_q += from tangent", 4, 0, 0}, {"g_phi += from quaternion", 3, 0, 0}};
    case kProjection:
      return {{"cull", 1, 0, 0},        {"mean2d", 2, 0, 0},
              {"conic", 3, 0, 1},        {"cov2d", 3, 0, 0},
              {"depth", 1, 0, 0},       {"radius", 1, 0, 0},
              {"v_mean", 3, 0, 2},       {"v_quat", 4, 0, 2},
              {"v_quat_tangent", 3, 0, 2}, {"v_log_scale", 3, 0, 2},
              {"camera center", 3, 0, 0}, {"rotmat_from_unit_wxyz", 9, 0, 0}};
    case kSh:
      return {{"color", 3, 0, 0}, {"v_coeffs", 48, 0, 0}, {"v_dir", 3, 0, 0},
              {"Y", 16, 0, 0},    {"dY", 48, 0, 0}};
    default:
      return {};
  }
}

struct Case {
  int kind = 0;
  std::string label;
  std::vector<double> in = std::vector<double>(kIn, 0.0);
  bool near_singular = false;  // projection with an ill-conditioned 2D covariance
};

// Random and hard cases of every kind, in double (the float run rounds them).
inline std::vector<Case> make_cases(int random_per_kind, unsigned seed = 12345u) {
  using smg::Quaternion;
  using smg::Vector3;
  using smg::Vector4;
  const double pi = 3.14159265358979323846;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  auto uniform = [&](double a, double b) {
    return std::uniform_real_distribution<double>(a, b)(rng);
  };
  auto unit3 = [&]() {
    Vector3<double> v(normal(rng), normal(rng), normal(rng));
    return Vector3<double>(v.normalized());
  };
  auto unit_quat = [&]() {
    Vector4<double> v(normal(rng), normal(rng), normal(rng), normal(rng));
    v.normalize();
    return Quaternion<double>(v(0), v(1), v(2), v(3));
  };
  auto set_q = [](Case& c, int at, const Quaternion<double>& q) {
    c.in[at] = q.w();
    c.in[at + 1] = q.x();
    c.in[at + 2] = q.y();
    c.in[at + 3] = q.z();
  };
  auto set_v = [](Case& c, int at, const Vector3<double>& v) {
    for (int k = 0; k < 3; ++k) c.in[at + k] = v(k);
  };
  std::vector<Case> cases;
  auto add = [&](int kind, const std::string& label) -> Case& {
    cases.push_back(Case{});
    cases.back().kind = kind;
    cases.back().label = label;
    return cases.back();
  };

  // Rotation vectors: random angles over [0, 2π - 0.3], small angles, and the branch points.
  // Jr^-1 has a pole at 2π (Log never returns more than π): 0.3 short of it, float rounding of
  // θ is amplified ~10x in coeff_d; 0.1 short, ~100x, beyond what a device-host comparison at
  // 1e-5 can resolve.
  std::vector<std::pair<std::string, Vector3<double>>> phis;
  for (int r = 0; r < random_per_kind; ++r) {
    double angle;
    if (r % 4 == 0)
      angle = std::pow(10.0, uniform(-9.0, 0.0));
    else if (r % 4 == 3)
      angle = uniform(pi, 2 * pi - 0.3);
    else
      angle = uniform(0.0, pi);
    phis.emplace_back("random", angle * unit3());
  }
  for (double angle : {0.0, 1e-300, 1e-12, 1e-8, 1e-4, 0.1 * (1 - 1e-7), 0.1, 0.1 * (1 + 1e-7),
                       0.9 * (1 - 1e-7), 0.9, 0.9 * (1 + 1e-7), pi - 1e-6, pi, pi + 1e-6,
                       2 * pi - 0.3}) {
    char label[64];
    std::snprintf(label, sizeof label, "hard: |phi| = %.17g", angle);
    phis.emplace_back(label, angle * unit3());
    phis.emplace_back(std::string(label) + " (x axis)", Vector3<double>(angle, 0, 0));
  }
  for (const auto& [label, phi] : phis) {
    set_v(add(kSo3Exp, label), 0, phi);
    set_v(add(kSo3Jacobians, label), 0, phi);
  }

  // Quaternions for log: any norm, both signs, near the identity and near 180°.
  for (int r = 0; r < random_per_kind; ++r) {
    Quaternion<double> q = unit_quat();
    q.coeffs() *= uniform(0.5, 2.0);
    set_q(add(kSo3Log, "random, |q| in [0.5, 2]"), 0, q);
  }
  {
    const Vector3<double> n = unit3();
    auto near = [&](double w, const char* label) {
      const double s = std::sqrt(std::max(0.0, 1 - w * w));
      set_q(add(kSo3Log, label), 0, Quaternion<double>(w, s * n(0), s * n(1), s * n(2)));
    };
    set_q(add(kSo3Log, "hard: identity"), 0, Quaternion<double>(1, 0, 0, 0));
    set_q(add(kSo3Log, "hard: -identity"), 0, Quaternion<double>(-1, 0, 0, 0));
    set_q(add(kSo3Log, "hard: w = 1, |v| = 1e-10"), 0, Quaternion<double>(1, 1e-10, 0, 0));
    set_q(add(kSo3Log, "hard: |v|/w at the series switch (1e-2 - 1e-12)"), 0,
          Quaternion<double>(1, 1e-2 - 1e-12, 0, 0));
    set_q(add(kSo3Log, "hard: |v|/w at the series switch (1e-2 + 1e-12)"), 0,
          Quaternion<double>(1, 1e-2 + 1e-12, 0, 0));
    near(0.0, "hard: 180 deg, w = 0");
    near(1e-8, "hard: near 180 deg, w = 1e-8");
    near(-1e-8, "hard: near 180 deg, w = -1e-8");
    near(1e-4, "hard: near 180 deg, w = 1e-4");
    near(-1e-4, "hard: near 180 deg, w = -1e-4");
    near(-0.5, "hard: w < 0");
    near(1 - 1e-15, "hard: near identity, w = 1 - 1e-15");
    set_q(add(kSo3Log, "hard: tiny norm 1e-6"), 0,
          Quaternion<double>(Quaternion<double>(unit_quat()).coeffs() * 1e-6));
  }

  // Products of unit quaternions, with the antipodal and near-180° pairs.
  for (int r = 0; r < random_per_kind + 8; ++r) {
    const Quaternion<double> a = unit_quat();
    Quaternion<double> b = unit_quat();
    std::string label = "random";
    switch (r) {
      case 0: b = a; label = "hard: b = a"; break;
      case 1: b = Quaternion<double>(-a.coeffs()); label = "hard: b = -a (antipodal)"; break;
      case 2:
        b = Quaternion<double>(-(a * smg::so3::exp(Vector3<double>(1e-7 * unit3()))).coeffs());
        label = "hard: b = -a Exp(1e-7 n) (antipodal, perturbed)";
        break;
      case 3:
        b = a * smg::so3::exp(Vector3<double>((pi - 1e-7) * unit3()));
        label = "hard: b = a Exp((pi - 1e-7) n) (near 180 deg)";
        break;
      case 4:
        b = a * smg::so3::exp(Vector3<double>(pi * unit3()));
        label = "hard: b = a Exp(pi n) (180 deg)";
        break;
      case 5: b = Quaternion<double>(0, 1, 0, 0); label = "hard: b = 180 deg about x"; break;
      case 6:
        b = Quaternion<double>(-(a * smg::so3::exp(Vector3<double>((pi - 1e-6) * unit3())))
                                    .coeffs());
        label = "hard: b = -a Exp((pi - 1e-6) n)";
        break;
      default: break;
    }
    Case& c = add(kQuatProducts, label);
    set_q(c, 0, a);
    set_q(c, 4, b);
    set_v(c, 8, Vector3<double>(3 * normal(rng), 3 * normal(rng), 3 * normal(rng)));
  }

  for (int r = 0; r < random_per_kind; ++r) {
    Quaternion<double> q = unit_quat();
    q.coeffs() *= uniform(0.2, 3.0);
    set_q(add(kQuatMatrices, "random, |q| in [0.2, 3]"), 0, q);
  }
  set_q(add(kQuatMatrices, "hard: (0, 0, 0, 1)"), 0, Quaternion<double>(0, 0, 0, 1));
  set_q(add(kQuatMatrices, "hard: w = -1e-9"), 0, Quaternion<double>(-1e-9, 0.6, 0.8, 0));
  set_q(add(kQuatMatrices, "hard: tiny norm 1e-8"), 0, Quaternion<double>(1e-8, -2e-8, 0, 3e-8));

  for (int r = 0; r < random_per_kind + 6; ++r) {
    const Quaternion<double> q = unit_quat();
    Vector3<double> delta = uniform(0.0, pi) * unit3();
    Quaternion<double> y = unit_quat();
    std::string label = "random";
    switch (r) {
      case 0: y = q; delta.setZero(); label = "hard: y = q, delta = 0"; break;
      case 1: y = Quaternion<double>(-q.coeffs()); label = "hard: y = -q (antipodal)"; break;
      case 2:
        y = q * smg::so3::exp(Vector3<double>((pi - 1e-7) * unit3()));
        label = "hard: y = q Exp((pi - 1e-7) n)";
        break;
      case 3: delta = 1e-9 * unit3(); label = "hard: delta = 1e-9"; break;
      case 4: delta = pi * unit3(); label = "hard: |delta| = pi"; break;
      case 5:
        y = q * smg::so3::exp(Vector3<double>(1e-8 * unit3()));
        label = "hard: y = q Exp(1e-8 n)";
        break;
      default: break;
    }
    Case& c = add(kManifold, label);
    set_q(c, 0, q);
    set_v(c, 4, delta);
    set_q(c, 7, y);
    for (int k = 0; k < 6; ++k) c.in[11 + k] = normal(rng);
  }

  for (int r = 0; r < random_per_kind + 1; ++r) {
    Quaternion<double> q = unit_quat();
    q.coeffs() *= r == 0 ? 1e-3 : uniform(0.1, 10.0);
    Case& c = add(kRotationGradient, r == 0 ? "hard: |q| = 1e-3" : "random, |q| in [0.1, 10]");
    set_q(c, 0, q);
    for (int k = 4; k < 18; ++k) c.in[k] = normal(rng);
  }

  // Projection: random cameras and visible Gaussians, then the hard ones.
  auto projection_case = [&](const std::string& label, const Vector3<double>& p_c,
                             const Vector3<double>& scales, double eps2d) -> Case& {
    Case& c = add(kProjection, label);
    const Quaternion<double> cam_q = unit_quat();
    const smg::Matrix3<double> R = cam_q.toRotationMatrix();
    const Vector3<double> t(normal(rng), normal(rng), normal(rng));
    const double fx = uniform(300, 800), fy = fx * uniform(0.9, 1.1);
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) c.in[proj::viewmat + 4 * r + k] = R(r, k);
      c.in[proj::viewmat + 4 * r + 3] = t(r);
    }
    c.in[proj::viewmat + 15] = 1;
    c.in[proj::fx] = fx;
    c.in[proj::fy] = fy;
    c.in[proj::cx] = 320 + uniform(-20, 20);
    c.in[proj::cy] = 240 + uniform(-20, 20);
    c.in[proj::width] = 640;
    c.in[proj::height] = 480;
    c.in[proj::near_plane] = 0.01;
    c.in[proj::far_plane] = 1e10;
    set_v(c, proj::mean, R.transpose() * (p_c - t));  // camera-space p_c
    Quaternion<double> q = unit_quat();
    q.coeffs() *= uniform(0.5, 2.0);
    set_q(c, proj::quat, q);
    set_v(c, proj::log_scale, scales.array().log().matrix());
    c.in[proj::eps2d] = eps2d;
    c.in[proj::radius_sigmas] = 3;
    for (int k = 0; k < 6; ++k) c.in[proj::v_mean2d + k] = normal(rng);
    return c;
  };
  for (int r = 0; r < random_per_kind; ++r) {
    const double z = uniform(0.5, 20);
    const Vector3<double> p_c(uniform(-0.25, 0.25) * z, uniform(-0.2, 0.2) * z, z);
    const Vector3<double> s(z * uniform(0.005, 0.1), z * uniform(0.005, 0.1),
                            z * uniform(0.005, 0.1));
    projection_case("random visible", p_c, s, 0.3);
  }
  {
    const double near = 0.01;
    projection_case("hard: near the camera plane, z = 1.001 near", Vector3<double>(1e-4, -2e-4, near * 1.001),
                    Vector3<double>(1e-5, 2e-5, 3e-5), 0.3);
    projection_case("hard: near the camera plane, z = 1.01 near", Vector3<double>(-1e-3, 5e-4, near * 1.01),
                    Vector3<double>(2e-5, 1e-5, 4e-5), 0.3);
    projection_case("hard: near the camera plane, x/z beyond the clamp",
                    Vector3<double>(0.02, 0.0, near * 1.001), Vector3<double>(1e-2, 2e-2, 1e-2),
                    0.3);
    projection_case("hard: beyond the field-of-view clamp, large", Vector3<double>(8, -7, 5),
                    Vector3<double>(2.5, 1.5, 2.0), 0.3);
    projection_case("hard: behind the camera", Vector3<double>(0.1, 0.1, -1),
                    Vector3<double>(0.1, 0.1, 0.1), 0.3);
    projection_case("hard: z = 0.999 near", Vector3<double>(0, 0, near * 0.999),
                    Vector3<double>(0.1, 0.1, 0.1), 0.3);
    projection_case("hard: outside the image", Vector3<double>(30, 0, 5),
                    Vector3<double>(0.01, 0.01, 0.01), 0.3);
    for (double ratio : {0.3, 0.1, 0.03, 0.01, 1e-3, 1e-5}) {
      for (double eps2d : {0.3, 0.0}) {
        char label[96];
        std::snprintf(label, sizeof label,
                      "hard: needle (thin/long scale %g, eps2d %g), near-singular 2D covariance",
                      ratio, eps2d);
        const double z = uniform(2, 6);
        projection_case(label, Vector3<double>(uniform(-0.1, 0.1) * z, uniform(-0.1, 0.1) * z, z),
                        Vector3<double>(0.3 * z, 0.3 * z * ratio, 0.3 * z * ratio), eps2d)
            .near_singular = true;
      }
    }
  }

  for (int r = 0; r < random_per_kind + 4; ++r) {
    Case& c = add(kSh, r < 4 ? "hard" : "random");
    c.in[0] = r % 4;  // degree
    Vector3<double> dir = uniform(0.1, 10) * unit3();
    if (r == 0) dir.setZero(), c.label = "hard: zero direction";
    if (r == 1) dir = Vector3<double>(2, 0, 0), c.label = "hard: direction along x";
    if (r == 2) dir = Vector3<double>(0, 0, -1e-3), c.label = "hard: short direction along -z";
    if (r == 3) dir = Vector3<double>(0.3, -0.4, 1.2), c.label = "hard: degree 3, fixed direction";
    set_v(c, 1, dir);
    for (int k = 0; k < 48; ++k) c.in[4 + k] = 0.5 * normal(rng);
    for (int k = 0; k < 3; ++k) c.in[52 + k] = normal(rng);
  }
  return cases;
}

// 2D covariance condition number a c / (a c - b²) of a projection case, computed in double
// from the case's own inputs (infinite when not positive definite; 1 when culled by depth).
inline double projection_condition(const Case& c) {
  const smg::splat::Camera<double> cam = camera_from(c.in.data());
  const double* in = c.in.data();
  smg::splat::detail::ProjectionState<double> st;
  const smg::splat::Cull cull = smg::splat::detail::projection_state(
      cam, smg::Vector3<double>(in[proj::mean], in[proj::mean + 1], in[proj::mean + 2]),
      smg::Vector4<double>(in[proj::quat], in[proj::quat + 1], in[proj::quat + 2],
                           in[proj::quat + 3]),
      smg::Vector3<double>(in[proj::log_scale], in[proj::log_scale + 1], in[proj::log_scale + 2]),
      in[proj::eps2d], &st);
  if (cull != smg::splat::Cull::none) return 1.0;
  return st.det > 0 ? st.a * st.c / st.det : std::numeric_limits<double>::infinity();
}

// Compares device outputs against host outputs of the same cases; prints one diagnostic per
// failing quantity (the first max_printed of them, with the case's inputs) and a per-kind summary
// of the worst error in units of the tolerance. Returns the number of failing cases.
//
// Error of a quantity (block): max_i |device_i - host_i| / max(floor, max_i |host_i|), against
// tol (1e-12 in double, 1e-5 in float). Projection: in the near-singular cases (needles) the
// conic and the gradients flowing through it are only as accurate as the 2D covariance's
// condition number κ allows (the conic's rounding error grows as ε κ, the gradients' as ε κ²:
// they cancel a component of size 1/λmin² down to 1/(λmin λmax)), so there the tolerance is
// max(tol, 64 ε κ) for the conic and max(tol, 64 ε κ²) for the gradients; random cases keep tol.
// In every projection case the gradients with respect to the Gaussian's shape (v_quat,
// v_quat_tangent, v_log_scale) are measured against one common scale, that of the three
// together (normwise: the gradient of a thin axis, or the component of v_quat left after the
// radial part of the rotation polynomial's gradient is projected out, is a cancelled small
// number whose own relative error says nothing). The radius is ceil(k sqrt(λmax)), so a
// difference of 1 is
// accepted where k sqrt(λmax) is within rounding of an integer; a cull decision that differs
// between device and host fails, except visible / singular at a κ within a factor 8 of the
// threshold 1 / (16 ε) (the decision rests on rounding there).
template <class S>
int compare(const std::vector<Case>& cases, const std::vector<S>& host,
            const std::vector<S>& device, double tol, const char* scalar_name,
            int max_printed = 20) {
  const double eps = std::numeric_limits<S>::epsilon();
  int failures = 0, printed = 0;
  std::vector<double> worst(kKindCount, 0.0);
  std::vector<std::string> worst_where(kKindCount);
  std::vector<int> counts(kKindCount, 0);
  auto print_case = [&](std::size_t n) {
    const Case& c = cases[n];
    std::printf("    inputs (%s, as given to both sides):", scalar_name);
    int last = kIn - 1;
    while (last > 0 && c.in[last] == 0.0) --last;
    for (int k = 0; k <= last; ++k)
      std::printf("%s%.17g", k % 6 == 0 ? "\n      " : " ", static_cast<double>(S(c.in[k])));
    std::printf("\n");
  };
  auto print_block = [&](const char* what, const S* h, const S* d, int size) {
    std::printf("    %-8s host  :", what);
    for (int k = 0; k < size; ++k) std::printf(" %.17g", static_cast<double>(h[k]));
    std::printf("\n    %-8s device:", what);
    for (int k = 0; k < size; ++k) std::printf(" %.17g", static_cast<double>(d[k]));
    std::printf("\n");
  };
  for (std::size_t n = 0; n < cases.size(); ++n) {
    const Case& c = cases[n];
    const S* h = host.data() + n * kOut;
    const S* d = device.data() + n * kOut;
    ++counts[c.kind];
    bool case_failed = false;
    auto fail = [&](const std::string& message, const S* hb, const S* db, int size) {
      if (!case_failed) ++failures;
      case_failed = true;
      if (printed++ >= max_printed) return;
      std::printf("test_cuda_core [%s] FAIL %s case %zu \"%s\": %s\n", scalar_name,
                  kind_name(c.kind), n, c.label.c_str(), message.c_str());
      if (hb) print_block("values", hb, db, size);
      print_case(n);
    };
    double kappa = 1.0;
    bool visible = true;
    if (c.kind == kProjection) {
      kappa = projection_condition(c);
      const int ch = static_cast<int>(h[0]), cd = static_cast<int>(d[0]);
      visible = ch == 0;
      if (ch != cd) {
        const int singular = static_cast<int>(smg::splat::Cull::singular);
        const double margin = 16 * eps * kappa;
        const bool borderline = (ch == 0 || ch == singular) && (cd == 0 || cd == singular) &&
                                margin > 0.125 && margin < 8;
        if (!borderline) {
          char m[256];
          std::snprintf(m, sizeof m,
                        "cull differs: host %s, device %s (2D covariance condition %.3g)",
                        smg::splat::cull_name(static_cast<smg::splat::Cull>(ch)),
                        smg::splat::cull_name(static_cast<smg::splat::Cull>(cd)), kappa);
          fail(m, nullptr, nullptr, 0);
        }
        continue;
      }
    }
    int offset = 0;
    for (const Block& b : blocks(c.kind)) {
      const S* hb = h + offset;
      const S* db = d + offset;
      offset += b.size;
      if (c.kind == kProjection && !visible && std::string(b.name) != "camera center" &&
          std::string(b.name) != "rotmat_from_unit_wxyz")
        continue;  // culled: only the cull code is defined
      double scale = b.floor, err = 0;
      if (c.kind == kProjection && b.conditioned == 2 && std::string(b.name) != "v_mean")
        for (int k = 0; k < 10; ++k)  // v_quat, v_quat_tangent, v_log_scale: outputs 14..23
          if (std::isfinite(static_cast<double>(h[14 + k])))
            scale = std::max(scale, std::abs(static_cast<double>(h[14 + k])));
      bool nonfinite_mismatch = false;
      for (int k = 0; k < b.size; ++k) {
        const double hv = static_cast<double>(hb[k]), dv = static_cast<double>(db[k]);
        if (!std::isfinite(hv) || !std::isfinite(dv)) {
          if (!(hv == dv || (std::isnan(hv) && std::isnan(dv)))) nonfinite_mismatch = true;
          continue;
        }
        scale = std::max(scale, std::abs(hv));
        err = std::max(err, std::abs(dv - hv));
      }
      double t = tol;
      if (c.near_singular && b.conditioned > 0)
        t = std::max(tol, 64 * eps * std::pow(kappa, b.conditioned));
      const double rel = scale > 0 ? err / scale : err;
      bool ok = !nonfinite_mismatch && (rel <= t || err <= std::numeric_limits<double>::min());
      if (!ok && c.kind == kProjection && std::string(b.name) == "radius" && err == 1.0) {
        // ceil at an integer boundary: accept when k sqrt(λmax) is within rounding of one.
        const double a = h[6], bb = h[7], cc = h[8];  // cov2d follows cull, mean2d, conic
        const double ht = 0.5 * (a + cc);
        const double r = c.in[proj::radius_sigmas] *
                         std::sqrt(ht + std::sqrt(std::max(ht * ht - (a * cc - bb * bb), 0.01)));
        ok = std::abs(r - std::round(r)) <= 64 * eps * r;
      }
      const double units = rel / t;
      if (units > worst[c.kind]) {
        worst[c.kind] = units;
        worst_where[c.kind] = std::string(b.name) + " in \"" + c.label + "\"";
      }
      if (!ok) {
        char m[256];
        std::snprintf(m, sizeof m,
                      "%s differs: max |device - host| = %.3g, scale %.3g, relative %.3g > "
                      "tolerance %.3g%s",
                      b.name, err, scale, rel, t,
                      nonfinite_mismatch ? " (non-finite value on one side only)" : "");
        fail(m, hb, db, b.size);
      }
    }
  }
  if (printed > max_printed)
    std::printf("test_cuda_core [%s]: %d more failures not printed\n", scalar_name,
                printed - max_printed);
  std::printf("test_cuda_core [%s]: %zu cases, %d failing; worst error per kind in units of the "
              "tolerance (%.0e):\n",
              scalar_name, cases.size(), failures, tol);
  for (int k = 0; k < kKindCount; ++k)
    std::printf("  %-17s %4d cases  worst %.3g  (%s)\n", kind_name(k), counts[k], worst[k],
                worst_where[k].empty() ? "-" : worst_where[k].c_str());
  return failures;
}

}  // namespace smg_cuda_test
