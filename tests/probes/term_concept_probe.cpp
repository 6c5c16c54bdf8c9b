// Compiled (-fsyntax-only) by the term_concept_* tests (tests/term_concept_expect.cmake): a term
// that does not model the concept of energy/block.hpp must stop the build at static_asserts
// naming what it lacks. PROBE_CASE selects the term:
//   1  a struct with only on(): every other member is named;
//   2  a complete term (TermDefaults) that names an Element without energy_of;
//   3  a complete term whose node() takes its Block by value of the wrong type.
#include "smg/energy/driver.hpp"

namespace probe {
using smg::Index;
using S = double;
using I = int;

#if PROBE_CASE == 1
struct Term {
  bool on() const { return true; }
};
#else
struct Element {
  bool reads_confidence() const { return false; }
};
struct Term : smg::detail::TermDefaults {
  struct Block {};
  template <class RO>
  void setup(const RO&, const smg::detail::TermShape&) {}
  bool on() const { return true; }
  Index reach() const { return 0; }
  Index slot_scalars(const smg::detail::BlockPlan&) const { return 0; }
  void bind(const smg::detail::BlockPlan&, S*, const smg::NeighborsView<S, I>&) {}
  Block begin(smg::detail::BlockView<S, I>&, S*) const { return {}; }
#if PROBE_CASE == 2
  using Element = probe::Element;
  Element element() const { return {}; }
  void node(const smg::detail::BlockView<S, I>&, Block&, Index, smg::RegularizerResult<S>&) const {}
#else
  struct Other {};
  void node(const smg::detail::BlockView<S, I>&, Other&, Index, smg::RegularizerResult<S>&) const {}
#endif
};
#endif
}  // namespace probe

int main() {
  probe::Term t;
  std::vector<double> x(3);
  smg::NeighborsView<double, int> g;
  (void)smg::detail::drive_views<double, int>(smg::PositionsView<const double>(x.data(), 1, 1), {}, false, g, {}, {},
                                              nullptr, {}, t);
  return 0;
}
