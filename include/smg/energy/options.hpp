// smg/energy/options.hpp — the options' vocabulary and the paper's four: gaps (GapList),
// Normalization, the penalties (E22), the stop-gradient (E24), AccelForm, the named-enum codec
// (enum_values), the checks every validate_options is written with, and the parameters of the
// confidence, C-ARAP, plain ARAP and LRM equations with their visitors and validation
// (docs/design.md "Confidence", "C-ARAP", "LRM", "Plain ARAP"; docs/math/energy.md). Defaults are
// the paper's (section 4.1) and docs/interop.md's flag defaults.
//
// Where the rest lives: a term's own options (AccelOptions, AngleOptions, RelrotOptions, and a new
// term's) sit in its header under energy/terms/, beside the equations they parameterise; the
// list of the fused step's terms, RegularizerOptions, RegularizerResult and for_each_term, is
// energy/term_list.hpp, written once from SMG_REGULARIZER_TERMS. The four here stay in one file
// because the separate operators (node_confidences, carap, arap, lrm) and their CUDA kernels take
// them without the fused step.
//
// Parameters are plain doubles whatever the Scalar of the computation: they are converted once
// per call. Every energy is a sum over terms "as in the paper"; Normalization::mean divides the
// energy (and its gradient) by the number of terms instead (documented per energy).
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <cstddef>
#include <initializer_list>
#include <sstream>
#include <string>
#include <type_traits>

#include "smg/core/status.hpp"

namespace smg {

// Per-frame node confidence c_{t,i} = v_{t,i} (c^m)^λm (c^r)^λr, equations (E3)-(E6).
struct ConfidenceOptions {
  double kappa_m = 2.5;   // κm: soft threshold of the motion factor (dimensionless)
  double kappa_r = 2.5;   // κr: soft threshold of the rigidity factor (dimensionless)
  double lambda_m = 1.0;  // λm: exponent of the motion factor
  double lambda_r = 1.0;  // λr: exponent of the rigidity factor
  double eps = 1e-4;      // ε: a length per frame, keeps the normalisers s^v, s^ℓ away from 0
};

// One temporal gap δ (frames) of C-ARAP / ARAP and its weight γ_δ.
struct Gap {
  int delta = 1;
  double weight = 1.0;
};

// The gaps of C-ARAP / ARAP: a short list with a fixed capacity, so that the option structs are
// plain values (no heap memory) that a GPU kernel can take by value. Behaves like a small
// std::vector<Gap> (initializer list, push_back, size, iteration). Appending beyond kCapacity
// keeps the first kCapacity gaps and marks the list as overflowed, which validate_options
// reports.
class GapList {
 public:
  static constexpr std::size_t kCapacity = 8;

  GapList() = default;
  GapList(std::initializer_list<Gap> gaps) {
    for (const Gap& g : gaps) push_back(g);
  }
  template <class It>
  GapList(It first, It last) {
    for (; first != last; ++first) push_back(*first);
  }

  void push_back(const Gap& g) {
    if (count_ < kCapacity)
      items_[count_++] = g;
    else
      overflowed_ = true;
  }
  void clear() {
    count_ = 0;
    overflowed_ = false;
  }
  std::size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  bool overflowed() const { return overflowed_; }
  const Gap& operator[](std::size_t k) const { return items_[k]; }
  Gap& operator[](std::size_t k) { return items_[k]; }
  const Gap* begin() const { return items_; }
  const Gap* end() const { return items_ + count_; }
  Gap* begin() { return items_; }
  Gap* end() { return items_ + count_; }

 private:
  Gap items_[kCapacity] = {};
  std::size_t count_ = 0;
  bool overflowed_ = false;
};

inline GapList default_gaps() { return {{1, 1.0}, {2, 1.0}, {4, 1.0}}; }

// How the terms of an energy are combined.
enum class Normalization {
  sum,   // Σ over all terms, as in the paper (default)
  mean,  // the sum divided by the number of terms (each energy documents its count)
};

// The penalty on a term's difference a with factor k and weight w (E22): squared k w ‖a‖² (the
// default), norm k w ‖a‖ (sub-gradient 0 at a = 0, as torch's norm), sqrt_weighted
// k sqrt(w ‖a‖² + ε) (the weight inside the root, as Dynamic 3D Gaussians writes its losses).
// Read by the smoothness term (E22) and by each part of the rigid energies (E24).
enum class Penalty { squared, norm, sqrt_weighted };
// The penalties and their names ("squared", "norm", "sqrt_weighted"), as the bindings spell them.
inline constexpr Penalty kPenalties[] = {Penalty::squared, Penalty::norm, Penalty::sqrt_weighted};
constexpr const char* to_string(Penalty p) {
  return p == Penalty::norm ? "norm" : p == Penalty::sqrt_weighted ? "sqrt_weighted" : "squared";
}
using AccelPenalty = Penalty;  // its first name, when only the smoothness term had it

// The rigid energies' stop-gradient (E24): the position of which endpoint of an edge i -> j gets
// no gradient from the energy (the rotations always do), as MoSca's multi-level ARAP detaches
// one end (`detach_nn`: the node whose frame expresses the edge, smg's row i; `detach_self`: the
// other, smg's neighbour j).
enum class StopGradient { none, row, neighbor };
// The values and their names ("none", "row", "neighbor"), as the bindings spell them.
inline constexpr StopGradient kStopGradients[] = {StopGradient::none, StopGradient::row,
                                                  StopGradient::neighbor};
constexpr const char* to_string(StopGradient g) {
  return g == StopGradient::row ? "row" : g == StopGradient::neighbor ? "neighbor" : "none";
}

// The rigid energies' frame (E24): whose rotation expresses edge i -> j, d = R_fᵀ(x_j − x_i).
// row: f = i, the paper's (E8); neighbor: f = j, as MoSca's ARAP writes its local coordinates
// (ℓ_ik = R_jᵀ(x_i − x_j), j = topo_ind[i, k]: −d, the same norms). With neighbor, edge i -> j's
// rotation gradient goes to R_j.
enum class RigidFrame { row, neighbor };
// The values and their names ("row", "neighbor"), as the bindings spell them.
inline constexpr RigidFrame kRigidFrames[] = {RigidFrame::row, RigidFrame::neighbor};
constexpr const char* to_string(RigidFrame f) { return f == RigidFrame::neighbor ? "neighbor" : "row"; }

// C-ARAP, equation (E9). Weights w̃_ij^t = w_ij (α + (1 − α) c_{t,j}) (E7).
struct CarapOptions {
  double alpha = 0.6;     // α in [0, 1]: lower bound of the confidence factor
  double lambda_c = 1.0;  // λc: vector-consistency term
  double lambda_l = 1.0;  // λl: length-preservation term
  GapList gaps = default_gaps();
  Normalization normalization = Normalization::sum;
  double weight = 1.0;    // overall factor on the energy and its gradient
  Penalty penalty = Penalty::squared;                // (E24): each part of (E9) under (E22)
  StopGradient stop_gradient = StopGradient::none;   // (E24): an endpoint's position held
  double penalty_eps = 1e-20;  // ε of sqrt_weighted (length²), finite and > 0; read by it only
  RigidFrame frame = RigidFrame::row;  // (E24): R_i (the paper's d, E8) or the neighbour's R_j
};

// Plain ARAP (ablations): C-ARAP with every confidence 1 and α = 1, i.e. w̃_ij^t = w_ij.
struct ArapOptions {
  double lambda_c = 1.0;
  double lambda_l = 1.0;
  GapList gaps = default_gaps();
  Normalization normalization = Normalization::sum;
  double weight = 1.0;
  Penalty penalty = Penalty::squared;
  StopGradient stop_gradient = StopGradient::none;
  double penalty_eps = 1e-20;
  RigidFrame frame = RigidFrame::row;
};

// LRM, equations (E11)-(E16).
struct LrmOptions {
  double alpha = 0.6;          // α of the edge weights (E7), normalised per neighbourhood
  double huber_delta = 0.01;   // δ_H: a velocity (length per frame)
  bool detach_omega = false;   // hold ω constant in the gradient (for comparison)
  Normalization normalization = Normalization::sum;
  double weight = 1.0;         // overall factor on the energy and its gradient
};

// The forms of the trajectory terms (E21, E23): second differences (acceleration) or first
// differences (velocity), read by the smoothness and the rotation-angle terms.
enum class AccelForm { acceleration, velocity };
// The forms and their names ("acceleration", "velocity"), as the bindings spell them.
inline constexpr AccelForm kAccelForms[] = {AccelForm::acceleration, AccelForm::velocity};
constexpr const char* to_string(AccelForm f) {
  return f == AccelForm::velocity ? "velocity" : "acceleration";
}

// The named enums of the options: enum_values(E{}) is the list of E's values, each with its
// name to_string(e). The bindings read and write an option of such a type by its name
// (smg_torch's string, smg_cli's choice flag) and validate_options refuses a value not listed,
// so an enum added (its list, to_string and this overload, here or in a term's header) needs no
// code in them.
constexpr const auto& enum_values(AccelForm) { return kAccelForms; }
constexpr const auto& enum_values(Penalty) { return kPenalties; }
constexpr const auto& enum_values(StopGradient) { return kStopGradients; }
constexpr const auto& enum_values(RigidFrame) { return kRigidFrames; }

namespace detail {
// SFINAE: O is T or const T (the visitors below take both).
template <class O, class T>
using IfOptions = std::enable_if_t<std::is_same<std::remove_const_t<O>, T>::value, int>;
}  // namespace detail

// for_each_option(options, f): f(name, field) for every field of one term's options, in
// declaration order, by the field's name; `options` const or mutable. Why: the bindings
// (smg_torch.regularizers, smg_cli regularizers) read, default and print every option through
// these lists, so an option is declared in its struct and named once, in the visitor beside it
// (here, or in its term's header). Field types: double, bool, GapList, Normalization and the
// named enums (enum_values).
template <class O, class F, detail::IfOptions<O, ConfidenceOptions> = 0>
void for_each_option(O& o, F&& f) {
  f("kappa_m", o.kappa_m);
  f("kappa_r", o.kappa_r);
  f("lambda_m", o.lambda_m);
  f("lambda_r", o.lambda_r);
  f("eps", o.eps);
}
namespace detail {
// The fields every energy term has: how its terms are combined and its overall factor.
template <class O, class F>
void for_each_scaling_option(O& o, F&& f) {
  f("normalization", o.normalization);
  f("weight", o.weight);
}
// The fields of every term with a penalty (E22) (as check_penalty_options checks them).
template <class O, class F>
void for_each_penalty_option(O& o, F&& f) {
  for_each_scaling_option(o, f);
  f("penalty", o.penalty);
  f("penalty_eps", o.penalty_eps);
}
// The fields of the trajectory terms, smoothness (E21) and rotation angles (E23) (as
// check_trajectory_options checks them).
template <class O, class F>
void for_each_trajectory_option(O& o, F&& f) {
  f("form", o.form);
  f("confidence_weighted", o.confidence_weighted);
  for_each_penalty_option(o, f);
}
// The fields C-ARAP and plain ARAP share (as check_rigidity_options checks them).
template <class O, class F>
void for_each_rigidity_option(O& o, F&& f) {
  f("lambda_c", o.lambda_c);
  f("lambda_l", o.lambda_l);
  f("gaps", o.gaps);
  f("stop_gradient", o.stop_gradient);
  for_each_penalty_option(o, f);
  f("frame", o.frame);
}
}  // namespace detail
template <class O, class F, detail::IfOptions<O, CarapOptions> = 0>
void for_each_option(O& o, F&& f) {
  f("alpha", o.alpha);
  detail::for_each_rigidity_option(o, f);
}
template <class O, class F, detail::IfOptions<O, ArapOptions> = 0>
void for_each_option(O& o, F&& f) {
  detail::for_each_rigidity_option(o, f);
}
template <class O, class F, detail::IfOptions<O, LrmOptions> = 0>
void for_each_option(O& o, F&& f) {
  f("alpha", o.alpha);
  f("huber_delta", o.huber_delta);
  f("detach_omega", o.detach_omega);
  detail::for_each_scaling_option(o, f);
}

namespace detail {
inline bool finite_in(double v, double lo, double hi) {
  return std::isfinite(v) && v >= lo && v <= hi;
}
inline Status check_nonneg(const char* what, const char* name, double v) {
  if (std::isfinite(v) && v >= 0) return Status::ok();
  std::ostringstream s;
  s << what << "." << name << " must be finite and >= 0, got " << v;
  return Status::error(s.str());
}
inline Status check_positive(const char* what, const char* name, double v) {
  if (std::isfinite(v) && v > 0) return Status::ok();
  std::ostringstream s;
  s << what << "." << name << " must be finite and > 0, got " << v;
  return Status::error(s.str());
}
inline Status check_alpha(const char* what, double v) {
  if (finite_in(v, 0.0, 1.0)) return Status::ok();
  std::ostringstream s;
  s << what << ".alpha must be in [0, 1], got " << v;
  return Status::error(s.str());
}
inline Status check_gaps(const char* what, const GapList& gaps) {
  if (gaps.overflowed()) {
    std::ostringstream s;
    s << what << ".gaps: more than " << GapList::kCapacity << " gaps";
    return Status::error(s.str());
  }
  for (std::size_t k = 0; k < gaps.size(); ++k) {
    if (gaps[k].delta < 1) {
      std::ostringstream s;
      s << what << ".gaps[" << k << "].delta must be >= 1, got " << gaps[k].delta;
      return Status::error(s.str());
    }
    if (!(std::isfinite(gaps[k].weight) && gaps[k].weight >= 0)) {
      std::ostringstream s;
      s << what << ".gaps[" << k << "].weight must be finite and >= 0, got " << gaps[k].weight;
      return Status::error(s.str());
    }
  }
  return Status::ok();
}
// A named enum (enum_values) holding one of its listed values: "AccelOptions.penalty must be
// squared, norm or sqrt_weighted, got 7".
template <class E>
inline Status check_enum(const char* what, const char* name, E v) {
  std::ostringstream s;
  const auto& values = enum_values(E{});
  const std::size_t n = sizeof(values) / sizeof(values[0]);
  for (std::size_t k = 0; k < n; ++k) {
    if (values[k] == v) return Status::ok();
    s << (k == 0 ? "" : k + 1 == n ? " or " : ", ") << to_string(values[k]);
  }
  std::ostringstream m;
  m << what << "." << name << " must be " << s.str() << ", got "
    << static_cast<long long>(static_cast<std::underlying_type_t<E>>(v));
  return Status::error(m.str());
}
// The first failing Status of `checks` (all evaluated, in order), or ok.
inline Status first_error(std::initializer_list<Status> checks) {
  for (const Status& s : checks)
    if (!s) return s;
  return Status::ok();
}
// The checks of every term with a penalty (E22) (`what` names the options type in the
// messages): weight >= 0, a listed penalty, ε finite and > 0.
template <class Options>
inline Status check_penalty_options(const char* what, const Options& o) {
  return first_error({check_nonneg(what, "weight", o.weight), check_enum(what, "penalty", o.penalty),
                      check_positive(what, "penalty_eps", o.penalty_eps)});
}
// The checks of the trajectory terms: a listed form, and the penalty's.
template <class Options>
inline Status check_trajectory_options(const char* what, const Options& o) {
  return first_error({check_enum(what, "form", o.form), check_penalty_options(what, o)});
}
// The checks C-ARAP and plain ARAP share: λc, λl >= 0, the gap list, a listed stop-gradient and
// frame, and the penalty's.
template <class Options>
inline Status check_rigidity_options(const char* what, const Options& o) {
  return first_error({check_nonneg(what, "lambda_c", o.lambda_c),
                      check_nonneg(what, "lambda_l", o.lambda_l), check_gaps(what, o.gaps),
                      check_enum(what, "stop_gradient", o.stop_gradient),
                      check_penalty_options(what, o), check_enum(what, "frame", o.frame)});
}
}  // namespace detail

inline Status validate_options(const ConfidenceOptions& o) {
  return detail::first_error({detail::check_positive("ConfidenceOptions", "kappa_m", o.kappa_m),
                              detail::check_positive("ConfidenceOptions", "kappa_r", o.kappa_r),
                              detail::check_nonneg("ConfidenceOptions", "lambda_m", o.lambda_m),
                              detail::check_nonneg("ConfidenceOptions", "lambda_r", o.lambda_r),
                              detail::check_positive("ConfidenceOptions", "eps", o.eps)});
}

inline Status validate_options(const CarapOptions& o) {
  if (Status s = detail::check_alpha("CarapOptions", o.alpha); !s) return s;
  return detail::check_rigidity_options("CarapOptions", o);
}

inline Status validate_options(const ArapOptions& o) {
  return detail::check_rigidity_options("ArapOptions", o);
}

inline Status validate_options(const LrmOptions& o) {
  return detail::first_error({detail::check_alpha("LrmOptions", o.alpha),
                              detail::check_positive("LrmOptions", "huber_delta", o.huber_delta),
                              detail::check_nonneg("LrmOptions", "weight", o.weight)});
}

// Plain ARAP is C-ARAP with α = 1 and no confidences (the caller passes none).
inline CarapOptions carap_options_for_arap(const ArapOptions& o) {
  CarapOptions c;
  c.alpha = 1.0;
  c.lambda_c = o.lambda_c;
  c.lambda_l = o.lambda_l;
  c.gaps = o.gaps;
  c.normalization = o.normalization;
  c.weight = o.weight;
  c.penalty = o.penalty;
  c.stop_gradient = o.stop_gradient;
  c.penalty_eps = o.penalty_eps;
  c.frame = o.frame;
  return c;
}

}  // namespace smg
