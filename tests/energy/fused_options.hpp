// tests/energy/fused_options.hpp — the options the fused-step tests (CPU: test_regularizers.cpp,
// CUDA: tests/cuda/test_cuda_regularizers.cu) run: a subset of the terms by bit mask, bit k for
// the k-th term of the library's list (smg::for_each_term: 1 confidence, 2 C-ARAP, 4 ARAP, 8 LRM,
// 16 smoothness, and so on for a term added to the list), and non-default values where a default
// would hide a mix-up between terms (ARAP's gaps share δ = 1 with C-ARAP's and add δ = 3 of their
// own).
#pragma once

#include <string>
#include <type_traits>
#include <utility>

#include "smg/energy/term_list.hpp"

namespace smg::test {

// The number of terms on the list (the masks run over 0 … 2^count − 1).
inline unsigned fused_term_count() {
  unsigned n = 0;
  RegularizerOptions o;
  for_each_term(o, [&](const char*, bool, const auto&) { ++n; });
  return n;
}

// The list index of the term named `term` (its mask bit is 1 << index); count if not listed.
inline unsigned fused_term_index(const char* term) {
  unsigned k = 0, found = fused_term_count();
  RegularizerOptions o;
  for_each_term(o, [&](const char* name, bool, const auto&) {
    if (std::string(name) == term) found = k;
    ++k;
  });
  return found;
}

// The mask with every term on.
inline unsigned fused_all_terms() { return (1u << fused_term_count()) - 1u; }

inline RegularizerOptions fused_options(unsigned mask) {
  RegularizerOptions o;
  unsigned k = 0;
  for_each_term(o, [&](const char*, bool& on, const auto&) { on = ((mask >> k++) & 1u) != 0; });
  o.accel.confidence_weighted = true;
  o.accel.weight = 0.5;
  o.arap.gaps = {{1, 1.0}, {3, 0.5}};
  o.arap.lambda_l = 0.7;
  o.lrm.huber_delta = 0.03;
  o.lrm.weight = 2.0;
  return o;
}

// Whether E is a named enum of the options (enum_values(E{}) lists its values).
template <class E, class = void>
struct HasEnumValues : std::false_type {};
template <class E>
struct HasEnumValues<E, std::void_t<decltype(enum_values(E{}))>> : std::true_type {};

// f(label, options) for every non-default value of every option of every term that is on in
// `base` that is a named enum (each listed value but the one base holds) or a bool (flipped):
// "carap.penalty=norm", "accel.confidence_weighted=false", ... Where that alone is not a valid
// call (validate_options: C-ARAP and ARAP share one stop_gradient), the option of that name and
// type is set on every term that is on, so that every value is still run. Returns the number of
// calls. Why: a new enum value or option of any term is run by the tests that use this (fused
// against separate, CUDA host scheme against CPU) with no edit to them.
template <class F>
int for_each_option_variant(const RegularizerOptions& base, F&& f) {
  int calls = 0;
  for_each_term(base, [&](const char* term, bool on, const auto& term_options) {
    if (!on) return;
    for_each_option(term_options, [&](const char* name, const auto& field) {
      using V = std::decay_t<decltype(field)>;
      auto run = [&](V value, const std::string& shown) {
        RegularizerOptions o = base;
        // This term's field of that name.
        for_each_term(o, [&](const char* t, bool, auto& opts) {
          if (std::string(t) != term) return;
          for_each_option(opts, [&](const char* n, auto& g) {
            if constexpr (std::is_same<std::decay_t<decltype(g)>, V>::value)
              if (std::string(n) == name) g = value;
          });
        });
        if (!validate_options(o))  // the same option on every term that is on
          for_each_term(o, [&](const char*, bool t_on, auto& opts) {
            if (!t_on) return;
            for_each_option(opts, [&](const char* n, auto& g) {
              if constexpr (std::is_same<std::decay_t<decltype(g)>, V>::value)
                if (std::string(n) == name) g = value;
            });
          });
        if (!validate_options(o)) return;
        ++calls;
        f(std::string(term) + "." + name + "=" + shown, o);
      };
      if constexpr (std::is_same<V, bool>::value) {
        run(!field, field ? "false" : "true");
      } else if constexpr (std::is_enum<V>::value) {
        if constexpr (HasEnumValues<V>::value)
          for (const V value : enum_values(V{}))
            if (value != field) run(value, to_string(value));
      }
    });
  });
  return calls;
}

}  // namespace smg::test
