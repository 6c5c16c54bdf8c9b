// examples/torch/smg_torch_options.hpp — the library's option structs from the Python
// arguments of smg_torch's operators, built once per call before the device dispatch (the CPU
// and CUDA implementations receive the same structs). The library's validators check the values
// (messages in the Python names, smg_torch_checks.hpp).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "smg/energy/block.hpp"
#include "smg/energy/term_list.hpp"
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

// ---- The fused step's options, term by term (smg::for_each_term, smg::for_each_option) ------
// Each option is a key of its term's dict (smg_torch.REGULARIZER_DEFAULTS, built from
// option_defaults below): the field's name, except that a GapList is the two keys "gaps" and
// "gap_weights" and a Normalization the bool "normalize". Read and written by the field's type,
// so a term or an option added to the library's lists reaches Python with no edit here.

// One option from its term's dict; messages are prefixed with the term ("carap.gaps[0]: ...").
inline void read_option(const py::dict& d, const char* name, double& v) { v = d[name].cast<double>(); }
inline void read_option(const py::dict& d, const char* name, bool& v) { v = d[name].cast<bool>(); }
inline void read_option(const py::dict& d, const char*, smg::Normalization& v) {
  v = normalization(d["normalize"].cast<bool>());
}
inline void read_option(const py::dict& d, const char*, smg::GapList& v) {
  const py::object gw = d["gap_weights"];
  std::optional<std::vector<double>> w;
  if (!gw.is_none()) w = gw.cast<std::vector<double>>();
  v = gap_list(d["gaps"].cast<py::sequence>(), w);
}
// A named enum (smg::enum_values: AccelForm, Penalty, ...) by its value's name.
template <class E, class = decltype(smg::enum_values(E{}))>
void read_option(const py::dict& d, const char* name, E& v) {
  const std::string given = d[name].cast<std::string>();
  std::string known;
  for (const E e : smg::enum_values(E{})) {
    if (given == smg::to_string(e)) {
      v = e;
      return;
    }
    known += std::string(known.empty() ? "'" : " or '") + smg::to_string(e) + "'";
  }
  value_error(std::string(name) + ": must be " + known + ", got '" + given + "'");
}

// One option's default into its term's dict (the inverse of read_option).
inline void write_option(py::dict& d, const char* name, double v) { d[name] = py::float_(v); }
inline void write_option(py::dict& d, const char* name, bool v) { d[name] = py::bool_(v); }
inline void write_option(py::dict& d, const char*, smg::Normalization v) {
  d["normalize"] = py::bool_(v == smg::Normalization::mean);
}
inline void write_option(py::dict& d, const char*, const smg::GapList& v) {
  py::list deltas, weights;
  bool all_one = true;
  for (const smg::Gap& g : v) {
    deltas.append(g.delta);
    weights.append(g.weight);
    all_one = all_one && g.weight == 1.0;
  }
  d["gaps"] = py::tuple(deltas);
  d["gap_weights"] = all_one ? py::object(py::none()) : py::object(py::tuple(weights));
}
template <class E, class = decltype(smg::enum_values(E{}))>
void write_option(py::dict& d, const char* name, E v) {
  d[name] = py::str(smg::to_string(v));
}

// options[term] -> that term's options; the term's prefix on every message ("lrm.alpha: ...").
template <class Options>
void read_term_options(const py::dict& d, const char* term, Options& o) {
  try {
    smg::for_each_option(o, [&](const char* name, auto& field) { read_option(d, name, field); });
  } catch (const py::value_error& e) {
    value_error(std::string(term) + "." + e.what());
  }
}

// {term: {option: default}} of RegularizerOptions{} and {term: on by default}.
inline py::dict option_defaults() {
  const smg::RegularizerOptions o;
  py::dict out;
  smg::for_each_term(o, [&](const char* term, bool, const auto& options) {
    py::dict d;
    smg::for_each_option(options, [&](const char* name, const auto& field) { write_option(d, name, field); });
    out[term] = d;
  });
  return out;
}
inline py::dict term_defaults() {
  const smg::RegularizerOptions o;
  py::dict out;
  smg::for_each_term(o, [&](const char* term, bool on, const auto&) { out[term] = py::bool_(on); });
  return out;
}

// The names of the energies of the fused step, in the order of its energies tensor.
inline std::vector<std::string> energy_names() {
  std::vector<std::string> names;
  smg::RegularizerResult<double> r;
  smg::RegularizerResult<double>::each_energy([&](const char* n, const double&) { names.emplace_back(n); }, r);
  return names;
}

inline smg::SkinOptions skin_options(bool lbs) {
  smg::SkinOptions o;
  o.method = lbs ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
  return o;
}

}  // namespace smg_torch
