// Compile-only: a kernel that calls every device-callable function of smg/core (SO(3),
// quaternions, the quaternion manifold, the per-element rotation-gradient conversions), of
// smg/splat (one Gaussian's projection and its vector-Jacobian product, spherical harmonics,
// the camera's accessors) and the energy terms made device-callable with them, in float and
// double. A function that loses SMG_HOST_DEVICE (or gains a host-only call) stops this file
// from compiling ("calling a __host__ function from a __global__ function").
#include <cstdint>

#include "device_usage.cuh"

#include "smg/core/quaternion.hpp"
#include "smg/core/quaternion_manifold.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/so3.hpp"
#include "smg/energy/elements/carap.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/elements/confidence.hpp"
#include "smg/energy/elements/lrm.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/splat/camera.hpp"
#include "smg/splat/gaussians.hpp"
#include "smg/splat/projection.hpp"
#include "smg/splat/sh.hpp"

namespace smg_device_usage_core_splat {

using smg::Index;
using smg::Matrix3;
using smg::Matrix34;
using smg::Matrix4;
using smg::Matrix43;
using smg::Quaternion;
using smg::Vector2;
using smg::Vector3;
using smg::Vector4;
using smg_device_usage::sink;

template <class S>
__global__ void core_usage(const S* in, S* out) {
  const Vector3<S> phi(in[0], in[1], in[2]);
  const Quaternion<S> a = smg::from_wxyz(in + 3);
  const Quaternion<S> b = smg::from_wxyz(Vector4<S>(in[7], in[8], in[9], in[10]));
  Matrix3<S> J1, J2;
  Matrix4<S> J4;

  // so3.hpp
  sink(out, smg::so3::hat(phi));
  sink(out, smg::so3::vee(smg::so3::hat(phi)));
  out[0] += smg::so3::detail::coeff_b(phi.squaredNorm()) +
            smg::so3::detail::coeff_c(phi.squaredNorm()) +
            smg::so3::detail::coeff_d(phi.squaredNorm());
  sink(out, smg::so3::right_jacobian(phi));
  sink(out, smg::so3::right_jacobian_inverse(phi));
  sink(out, smg::so3::left_jacobian(phi));
  sink(out, smg::so3::exp(phi).coeffs());
  sink(out, smg::so3::exp(phi, &J1).coeffs());
  sink(out, smg::so3::log(a));
  sink(out, smg::so3::log(a, &J1));
  sink(out, smg::so3::rotate(a, phi, &J1, &J2));
  sink(out, smg::so3::inverse_rotate(a, phi, &J1, &J2));
  sink(out, smg::so3::compose(a, b, &J1, &J2).coeffs());
  sink(out, smg::so3::inverse(a, &J1).coeffs());
  sink(out, smg::so3::between(a, b, &J1, &J2).coeffs());
  out[0] += smg::so3::angular_distance(a, b);
  sink(out, J1);
  sink(out, J2);

  // quaternion.hpp
  sink(out, smg::to_wxyz(a));
  smg::to_wxyz(b, out + 1);
  sink(out, smg::quat_left_matrix(a));
  sink(out, smg::quat_right_matrix(b));
  sink(out, smg::quat_tangent_jacobian(a));
  sink(out, smg::normalized(a).coeffs());
  sink(out, smg::normalized(a, &J4).coeffs());
  sink(out, J4);
  sink(out, smg::canonical(b).coeffs());

  // quaternion_manifold.hpp
  S q4[4], J12[12];
  smg::quaternion_manifold::plus(in + 3, in, q4);
  smg::quaternion_manifold::minus(in + 3, in + 7, q4);
  smg::quaternion_manifold::plus_jacobian(in + 3, J12);
  smg::quaternion_manifold::minus_jacobian(in + 3, J12);
  sink(out, smg::quaternion_manifold::plus_jacobian(a));
  sink(out, smg::quaternion_manifold::minus_jacobian(a));
  sink(out, smg::quaternion_manifold::ambient_jacobian(Eigen::Matrix<S, 2, 3>::Ones().eval(), a));
  out[0] += q4[0] + J12[0];

  // rotation_gradient.hpp (the per-element conversions)
  smg::add_quaternion_gradient_from_tangent(in + 3, in, out + 2);
  smg::add_tangent_gradient_from_quaternion(in + 3, in + 7, out + 6);
}

template <class S>
__global__ void splat_usage(smg::splat::Camera<S> cam, const S* in, S* out) {
  namespace sp = smg::splat;
  const Vector3<S> mean(in[0], in[1], in[2]);
  const Vector4<S> quat(in[3], in[4], in[5], in[6]);
  const Vector3<S> log_scale(in[7], in[8], in[9]);

  // camera.hpp
  const sp::Camera<S> cam2 =
      sp::Camera<S>::from_K(cam.viewmat, Matrix3<S>::Identity(), cam.width, cam.height);
  sink(out, cam2.rotation());
  sink(out, cam2.translation());
  sink(out, cam.center());

  // projection.hpp
  sink(out, sp::rotmat_from_unit_wxyz(quat));
  sink(out, sp::rotmat_from_unit_wxyz_vjp(quat, Matrix3<S>::Identity().eval()));
  S l[4];
  sp::detail::fov_limits(cam, l, l + 1, l + 2, l + 3);
  sp::detail::ProjectionState<S> st;
  const sp::Cull c0 = sp::detail::projection_state(cam, mean, quat, log_scale, S(0.3), &st);
  sp::ProjectedGaussian<S> p;
  const sp::Cull c = sp::project_gaussian(cam, mean, quat, log_scale, S(0.3), S(3), &p);
  out[0] += S(sp::cull_name(c)[0]) + S(int(c0)) + l[0] + st.det;
  if (c == sp::Cull::none) {
    Vector3<S> v_mean, v_quat_tangent, v_log_scale;
    Vector4<S> v_quat;
    sp::project_gaussian_vjp(cam, mean, quat, log_scale, S(0.3), p.conic, Vector2<S>(in[10], in[11]),
                             Vector3<S>(in[12], in[13], in[14]), in[15], &v_mean, &v_quat,
                             &v_quat_tangent, &v_log_scale);
    sp::project_gaussian_vjp<S>(cam, mean, quat, log_scale, S(0.3), p.conic, Vector2<S>::Ones(),
                                Vector3<S>::Ones(), S(1), &v_mean, nullptr, nullptr, nullptr);
    sink(out, v_mean);
    sink(out, v_quat);
    sink(out, v_quat_tangent);
    sink(out, v_log_scale);
  }

  // sh.hpp
  constexpr int K = sp::sh_basis_count(3);
  S Y[K], dY[3 * K], coeffs[3 * K], v_coeffs[3 * K], color[3];
  for (int k = 0; k < 3 * K; ++k) coeffs[k] = in[k % 16];
  sp::sh_basis(3, mean, Y);
  sp::sh_basis(3, mean, Y, dY);
  sp::sh_to_color(3, 3, mean, coeffs, color);
  sink(out, sp::sh_to_color_vjp(3, 3, mean, coeffs, color, v_coeffs));
  out[0] += Y[K - 1] + dY[3 * K - 1] + v_coeffs[0];

  // gaussians.hpp
  sp::GaussianParams<S> g;
  g.means = smg::TableView<const S, 3>(in, 1);
  g.colors = smg::TableView<const S, Eigen::Dynamic>(in, 1, 3);
  out[0] += S(g.count() + g.channels());
}

// The energy terms made device-callable with the CUDA groundwork (energy/*.hpp).
template <class S, class I>
__global__ void energy_usage(smg::PositionsView<const S> positions, smg::NeighborsView<S, I> graph,
                             smg::ConfidenceConstants<S> constants, const S* velocity,
                             const S* edge_change, S* out) {
  const Index i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= graph.nodes()) return;
  using L = smg::Literal<S>;
  S px, py, pz, q, r[4], sc, sl;
  out[0] += smg::carap_term(S(1), S(0.1), S(0.2), S(0.3), S(0.4), L(1), L(0.5), px, py, pz, q);
  out[0] += smg::carap_term_energy(S(1), S(0.1), S(0.2), S(0.3), S(0.4), L(1), L(0.5));
  smg::carap_term_residual(S(1), S(0.1), S(0.2), S(0.3), S(0.4), L(1), L(0.5), r, sc, sl);
  out[0] += px + py + pz + q + r[0] + sc + sl;
  out[0] += smg::confidence_edge_weight(S(0.5), L(0.2), S(0.7)) + smg::lrm_mu_factor<S>();
  const smg::VelocityFrames f = smg::velocity_frames(0, positions.frames());
  const S W = smg::detail::row_weight(graph, i);
  const S inv_w = W > S(0) ? S(1) / W : S(0);
  S motion, rigidity;
  out[0] += smg::confidence_edge_change(positions, graph, inv_w, f.plus, i);
  out[0] += smg::confidence_node(velocity, edge_change, graph, inv_w, f.minus, i, constants,
                                 &motion, &rigidity);
  S R[9];
  smg::detail::rotation_from_wxyz(velocity, R);
  out[0] += motion + rigidity + R[0];
  S dx, dy, dz, fx, fy, fz, rx, ry, rz;
  smg::carap_edge_vector(R, S(0.1), S(0.2), S(0.3), dx, dy, dz);
  smg::carap_edge_backprop(R, S(1), S(2), S(3), S(0.5), S(2), S(0.1), S(0.2), S(0.3), dx, dy, dz,
                           fx, fy, fz, rx, ry, rz);
  out[0] += fx + fy + fz + rx + ry + rz;
  // The view accessors the functions above do not reach themselves.
  out[0] += positions(f.plus, i).sum() + graph.weights.row(i).sum() + S(positions.size()) +
            S(graph.indices.size() + positions.empty() + graph.weights.empty());
}

template __global__ void core_usage<float>(const float*, float*);
template __global__ void core_usage<double>(const double*, double*);
template __global__ void splat_usage<float>(smg::splat::Camera<float>, const float*, float*);
template __global__ void splat_usage<double>(smg::splat::Camera<double>, const double*, double*);
template __global__ void energy_usage<float, std::int32_t>(
    smg::PositionsView<const float>, smg::NeighborsView<float, std::int32_t>,
    smg::ConfidenceConstants<float>, const float*, const float*, float*);
template __global__ void energy_usage<double, std::int64_t>(
    smg::PositionsView<const double>, smg::NeighborsView<double, std::int64_t>,
    smg::ConfidenceConstants<double>, const double*, const double*, double*);

}  // namespace smg_device_usage_core_splat
