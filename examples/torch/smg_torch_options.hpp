// examples/torch/smg_torch_options.hpp — the library's option structs from the Python
// arguments of smg_torch's operators, built once per call before the device dispatch (the CPU
// and CUDA implementations receive the same structs). The library's validators check the values
// (messages in the Python names, smg_torch_checks.hpp).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "smg/energy/options.hpp"
#include "smg/skin/skin_views.hpp"
#include "smg_torch_checks.hpp"

namespace smg_torch {

// Gap list (gaps: Python ints, each in [1, 10^6]; gap_weights: one per gap or None = all 1).
inline smg::GapList gap_list(const py::sequence& gaps, const std::optional<std::vector<double>>& w) {
  const std::size_t n = py::len(gaps);
  if (n == 0) value_error("gaps: needs at least one gap");
  if (w && w->size() != n)
    value_error("gap_weights: needs one weight per gap (" + std::to_string(n) + "), got " +
                std::to_string(w->size()));
  smg::GapList list;
  for (std::size_t k = 0; k < n; ++k)
    list.push_back({static_cast<int>(int_arg(gaps[k], "gaps[" + std::to_string(k) + "]", 1, 1000000)),
                    w ? (*w)[k] : 1.0});
  return list;
}

inline smg::Normalization normalization(bool normalize) {
  return normalize ? smg::Normalization::mean : smg::Normalization::sum;
}

inline smg::ConfidenceOptions confidence_options(double kappa_m, double kappa_r, double lambda_m,
                                                 double lambda_r, double eps) {
  smg::ConfidenceOptions o;
  o.kappa_m = kappa_m;
  o.kappa_r = kappa_r;
  o.lambda_m = lambda_m;
  o.lambda_r = lambda_r;
  o.eps = eps;
  return o;
}

// C-ARAP (plain = false) or plain ARAP (E9 with c = 1, alpha = 1): both option structs, the
// operator reads the one it needs.
struct CarapCall {
  bool plain = false;
  smg::CarapOptions carap;
  smg::ArapOptions arap;
};

inline CarapCall carap_options(bool plain, double alpha, double lambda_c, double lambda_l,
                               const py::sequence& gaps,
                               const std::optional<std::vector<double>>& gap_weights,
                               bool normalize) {
  CarapCall c;
  c.plain = plain;
  c.carap.alpha = alpha;
  c.carap.lambda_c = c.arap.lambda_c = lambda_c;
  c.carap.lambda_l = c.arap.lambda_l = lambda_l;
  c.carap.gaps = c.arap.gaps = gap_list(gaps, gap_weights);
  c.carap.normalization = c.arap.normalization = normalization(normalize);
  return c;
}

inline smg::LrmOptions lrm_options(double alpha, double huber_delta, bool detach_omega,
                                   bool normalize) {
  smg::LrmOptions o;
  o.alpha = alpha;
  o.huber_delta = huber_delta;
  o.detach_omega = detach_omega;
  o.normalization = normalization(normalize);
  return o;
}

inline smg::SkinOptions skin_options(bool lbs) {
  smg::SkinOptions o;
  o.method = lbs ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
  return o;
}

}  // namespace smg_torch
