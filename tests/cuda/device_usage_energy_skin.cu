// Compile-only: a kernel that calls every device-callable function of the LRM neighbourhood
// solve (smg/energy/elements/lrm.hpp, the scalar lane helpers of smg/energy/lanes.hpp), of the dual
// quaternions (smg/core/dual_quaternion.hpp) and of the per-point skinning (smg/skin/
// blend_point.hpp, weights_point.hpp), in float and double. A function that loses
// SMG_HOST_DEVICE (or gains a host-only call) stops this file from compiling.
#include <cstdint>

#include "device_usage.cuh"

#include "smg/core/dual_quaternion.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/elements/lrm.hpp"
#include "smg/skin/blend_point.hpp"
#include "smg/skin/weights_point.hpp"

namespace smg_device_usage_energy_skin {

using smg::Index;
using smg::Quaternion;
using smg::Vector3;
using smg_device_usage::sink;

template <class S>
__global__ void lrm_usage(const S* in, S* out) {
  namespace d = smg::detail;
  // lanes.hpp (scalar lanes)
  const S z = d::lane_constant<S>(smg::Literal<S>(0));
  const bool m = d::lane_greater(in[0], z);
  out[0] += d::lane_select(m, d::lane_sqrt(in[0]), z);
  // Ldlt3
  const d::Ldlt3<S> L(S(4), in[1], in[2], S(5), in[3], S(6));
  S x0, x1, x2;
  L.solve(in[4], in[5], in[6], x0, x1, x2);
  out[0] += x0 + x1 + x2;
  // lrm_neighborhood with gradient and ω, and without gradient.
  constexpr Index K = 4;
  S x[3 * K], u[3 * K], a[K], scratch[11 * K], gx[3 * K], gu[3 * K], om[3];
  for (Index k = 0; k < 3 * K; ++k) {
    x[k] = in[k];
    u[k] = in[k + 12];
  }
  for (Index k = 0; k < K; ++k) a[k] = smg::confidence_edge_weight(in[k], smg::Literal<S>(0.5), in[k + 4]);
  d::LrmParams<S> p;
  p.huber_delta = smg::Literal<S>(0.01);
  p.mu_factor = smg::lrm_mu_factor<S>();
  p.gradient = true;
  out[0] += d::lrm_neighborhood<S, S>(K, x, u, a, p, scratch, gx, gu, om);
  p.gradient = false;
  p.detach_omega = true;
  out[0] += d::lrm_neighborhood<S, S>(K, x, u, a, p, scratch, gx, gu);
  for (Index k = 0; k < 3 * K; ++k) out[0] += gx[k] + gu[k];
  out[0] += om[0] + om[1] + om[2];
}

template <class S>
__global__ void dual_quaternion_usage(const S* in, S* out) {
  const Quaternion<S> q = Quaternion<S>(in[0], in[1], in[2], in[3]).normalized();
  const Vector3<S> t(in[4], in[5], in[6]), pt(in[7], in[8], in[9]);
  smg::Matrix83<S> Jq, Jt;
  smg::Matrix8<S> Ja, Jb;
  smg::Matrix38<S> Jd;
  smg::Matrix3<S> Jp;
  const smg::DualQuaternion<S> a = smg::dual_quaternion_from_rotation_translation(q, t, &Jq, &Jt);
  const smg::DualQuaternion<S> b = smg::dual_quaternion_from_rotation_translation(q, pt);
  sink(out, Jq);
  sink(out, Jt);
  sink(out, a.coeffs_wxyz());
  sink(out, smg::DualQuaternion<S>::from_coeffs_wxyz(b.coeffs_wxyz()).coeffs_wxyz());
  sink(out, smg::DualQuaternion<S>::identity().coeffs_wxyz());
  Quaternion<S> r;
  Vector3<S> tr;
  smg::dual_quaternion_to_rotation_translation(a, &r, &tr);
  sink(out, r.coeffs());
  sink(out, tr);
  sink(out, smg::dual_quaternion_product(a, b, &Ja, &Jb).coeffs_wxyz());
  sink(out, Ja);
  sink(out, Jb);
  sink(out, smg::dual_quaternion_conjugate(a, &Ja).coeffs_wxyz());
  sink(out, smg::dual_quaternion_normalized(a, &Jb).coeffs_wxyz());
  sink(out, smg::dual_quaternion_transform_point(a, pt, &Jd, &Jp));
  sink(out, Jd);
  sink(out, Jp);
  sink(out, smg::detail::pure(t).coeffs());
  sink(out, smg::detail::conj_matrix<S>());
}

template <class S>
__global__ void skin_usage(const S* in, S* out) {
  constexpr Index D = 3;
  smg::SkinDriver<S> d[D];
  Vector3<S> x[D];
  S sigma[D], w[D], gw[D], gs[D];
  for (Index k = 0; k < D; ++k) {
    d[k].x_ref = Vector3<S>(in[k], in[k + 1], in[k + 2]);
    d[k].x_t = Vector3<S>(in[k + 3], in[k + 4], in[k + 5]);
    d[k].q_ref = Quaternion<S>(in[k + 6], in[k + 7], in[k + 8], in[k + 9]).normalized();
    d[k].q_t = Quaternion<S>(in[k + 10], in[k + 11], in[k + 12], in[k + 13]).normalized();
    x[k] = d[k].x_ref;
    sigma[k] = S(0.5) + in[k];
    gw[k] = in[k + 20];
  }
  const Vector3<S> p(in[30], in[31], in[32]);
  const Quaternion<S> qp = Quaternion<S>(in[33], in[34], in[35], in[36]).normalized();
  // weights_point.hpp
  Vector3<S> Jwp[D], Jwx[D * D], gx[D];
  S Jws[D * D];
  out[0] += smg::skinning_weights_point<S>(p, D, x, sigma, w, Jwp, Jwx, Jws) ? S(1) : S(0);
  for (Index k = 0; k < D; ++k) {
    d[k].weight = w[k];
    sink(out, Jwp[k]);
  }
  Vector3<S> g_p = Vector3<S>::Zero();
  smg::skinning_weights_point_vjp<S>(p, D, x, sigma, w, gw, &g_p, gx, gs);
  sink(out, g_p);
  // blend_point.hpp, both methods
  for (const smg::SkinMethod method : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
    Vector3<S> po;
    Quaternion<S> qo;
    smg::SkinDriverJacobian<S> Jd[D];
    smg::SkinPointJacobian<S> Jpt;
    smg::skin_point<S>(method, d, D, p, qp, &po, &qo, Jd, &Jpt);
    sink(out, po);
    sink(out, qo.coeffs());
    sink(out, Jd[0]);
    sink(out, Jpt);
    smg::SkinDriverGradient<S> g[D];
    Vector3<S> gpp, gphi;
    smg::skin_point_vjp<S>(method, d, D, p, qp, po, Vector3<S>(in[37], in[38], in[39]), g, &gpp,
                           &gphi);
    sink(out, g[1].phi_t);
    sink(out, Vector3<S>(gpp + gphi));
    // The detail layer the DQB kernels call.
    smg::detail::SkinBlendState<S> st;
    smg::detail::skin_blend_forward(method, d, D, p, qp, st);
    smg::detail::skin_blend_backward(
        method, d, D, p, qp, st, po, gphi,
        [&](Index k, const smg::SkinDriverGradient<S>& gk) { out[k] += gk.weight; }, gpp, gphi);
    sink(out, gpp);
  }
}

template __global__ void lrm_usage<float>(const float*, float*);
template __global__ void lrm_usage<double>(const double*, double*);
template __global__ void dual_quaternion_usage<float>(const float*, float*);
template __global__ void dual_quaternion_usage<double>(const double*, double*);
template __global__ void skin_usage<float>(const float*, float*);
template __global__ void skin_usage<double>(const double*, double*);

}  // namespace smg_device_usage_energy_skin
