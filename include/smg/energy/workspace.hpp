// smg/energy/workspace.hpp — reusable scratch memory for the energies.
//
// A trainer calls the energies every iteration; passing the same EnergyWorkspace each time makes
// the calls allocation-free after the first (buffers only grow). Passing nullptr is fine too: the
// call then uses a temporary workspace. One workspace serves one call at a time (not shared
// between threads); the energies parallelise internally.
#pragma once

#include "smg/core/config.hpp"

#include <cstddef>
#include <cstdint>
#include <vector>


namespace smg {

template <class S>
class EnergyWorkspace {
 public:
  // At least n scalars of the named buffer, contents unspecified.
  S* spill(std::size_t n) { return grow(spill_, n); }              // C-ARAP: frames past a block
  S* scratch(std::size_t n) { return grow(scratch_, n); }          // per-chunk SoA scratch
  // At least n scalars of the per-chunk scratch starting on a 64-byte boundary. Why: Eigen's
  // packet sums (sum_array) split an array's unaligned head off, so a sum's rounding depends on
  // where the array lies; with slots of an aligned_slot_size and this base, every slot has the
  // same alignment, and a result does not depend on which slot (thread) computed it.
  S* scratch_aligned(std::size_t n) {
    S* base = grow(scratch_, n + kAlignScalars);
    if constexpr (kAlignScalars == 1) return base;  // an autodiff scalar: nothing to align
    const std::size_t mis = reinterpret_cast<std::uintptr_t>(base) % 64;  // a multiple of sizeof(S)
    return mis == 0 ? base : base + (64 - mis) / sizeof(S);
  }
  // n rounded up to whole 64-byte lines, so that consecutive slots stay 64-byte aligned.
  static std::size_t aligned_slot_size(std::size_t n) { return (n + kAlignScalars - 1) / kAlignScalars * kAlignScalars; }
  S* velocity_grad(std::size_t n) { return grow(velocity_grad_, n); }  // LRM: dL/du [T][N][3]
  S* velocity(std::size_t n) { return grow(velocity_, n); }            // LRM: u [T][N][3]
  S* rotation_grad(std::size_t n) { return grow(rotation_grad_, n); }  // C-ARAP: tangent before raw

  // Bytes currently held.
  std::size_t bytes() const {
    return sizeof(S) *
           (spill_.size() + scratch_.size() + velocity_grad_.size() +
            velocity_.size() + rotation_grad_.size());
  }
  // Returns the memory.
  void release() { *this = EnergyWorkspace(); }

 private:
  // 16 scalars: 64 bytes of float, two lines of double (the fused step's RegularizerPlan::kAlign
  // counts the same slack); 1 for a scalar type that does not divide a line (autodiff).
  static constexpr std::size_t kAlignScalars = 64 % sizeof(S) == 0 && sizeof(S) <= 8 ? 16 : 1;
  static S* grow(std::vector<S>& v, std::size_t n) {
    if (v.size() < n) v.resize(n);
    return v.data();
  }
  std::vector<S> spill_, scratch_, velocity_grad_, velocity_, rotation_grad_;
};

namespace detail {
// The caller's workspace, or a local one for this call.
template <class S>
class WorkspaceRef {
 public:
  explicit WorkspaceRef(EnergyWorkspace<S>* ws) : ws_(ws ? ws : &local_) {}
  EnergyWorkspace<S>& operator*() { return *ws_; }
  EnergyWorkspace<S>* operator->() { return ws_; }

 private:
  EnergyWorkspace<S> local_;
  EnergyWorkspace<S>* ws_;
};
}  // namespace detail

}  // namespace smg
