// examples/trainer/variant.hpp — the ablation ladder (issue 7, item 3; the paper's Table 5).
//
// One flag picks what regularises the node trajectories and which graph drives the Gaussians:
//
//   variant    graph (regulariser + skinning)   rigidity term     LRM
//   base       geometric KNN (skinning only)    none              no
//   mosca      geometric KNN                    plain ARAP        no
//   smg-only   semantic (gated) KNN             plain ARAP        no
//   no-carap   semantic                         plain ARAP        yes
//   no-lrm     semantic                         C-ARAP            no
//   full       semantic                         C-ARAP            yes
//
// Everything else (data term, photometric loss, iteration counts, learning rates) is the same
// for every variant. LRM, where on, always uses the confidence-aware weights w~ (E7): the
// paper's LRM is defined with them, so "no-carap" removes only the confidences from the
// rigidity term.
#pragma once

#include <string>
#include <vector>

namespace trainer {

enum class Variant { base, mosca, smg_only, no_carap, no_lrm, full };
enum class Rigidity { none, arap, carap };

struct VariantSpec {
  Variant variant = Variant::full;
  bool semantic_graph = true;   // gate the KNN with the node descriptors (tau)
  Rigidity rigidity = Rigidity::carap;
  bool lrm = true;
};

inline const std::vector<std::string>& variant_names() {
  static const std::vector<std::string> names = {"base", "mosca", "smg-only", "no-carap", "no-lrm", "full"};
  return names;
}

inline std::string to_string(Variant v) { return variant_names()[static_cast<std::size_t>(v)]; }

// The spec of a variant by name; false if the name is unknown.
inline bool parse_variant(const std::string& name, VariantSpec* out) {
  const auto& names = variant_names();
  for (std::size_t k = 0; k < names.size(); ++k) {
    if (names[k] != name) continue;
    VariantSpec s;
    s.variant = static_cast<Variant>(k);
    switch (s.variant) {
      case Variant::base: s = {s.variant, false, Rigidity::none, false}; break;
      case Variant::mosca: s = {s.variant, false, Rigidity::arap, false}; break;
      case Variant::smg_only: s = {s.variant, true, Rigidity::arap, false}; break;
      case Variant::no_carap: s = {s.variant, true, Rigidity::arap, true}; break;
      case Variant::no_lrm: s = {s.variant, true, Rigidity::carap, false}; break;
      case Variant::full: s = {s.variant, true, Rigidity::carap, true}; break;
    }
    *out = s;
    return true;
  }
  return false;
}

inline VariantSpec variant_spec(Variant v) {
  VariantSpec s;
  parse_variant(to_string(v), &s);
  return s;
}

}  // namespace trainer
