// Compile-only: the per-(frame, node) step of every Element of the fused step's term list
// (smg::detail::RegularizerTermSet, energy/term_list.hpp), each in a kernel of its own and all of
// them in one, in float with int32 and double with int64 graphs. The Elements are read from the
// list through its apply(), as the CUDA driver reads them (smg::cuda::detail::ListElements), and
// called through the driver's dispatch (ElementPack::at: the step's signature follows its
// kReadsRotations / kReadsGraph): a term added to the list with an Element is compiled for the
// device here with no edit of this file, and a step that loses SMG_HOST_DEVICE (or gains a
// host-only call) stops it from compiling. The device functions the terms without an Element
// use (C-ARAP's, the confidences', LRM's) are listed in device_usage_core_splat.cu and
// device_usage_energy_skin.cu.
#include <cstdint>
#include <tuple>

#include "smg/cuda/driver.cuh"

namespace smg_device_usage_term_elements {

namespace cd = smg::cuda::detail;
using smg::Index;

template <class S, class I, class Pack>
__global__ void elements_usage(Pack pack, smg::PositionsView<const S> x, smg::QuaternionsView<const S> q,
                               const S* conf, smg::detail::ElementGraph<S, I> graph, S* grad_x, S* grad_tangent,
                               S* grad_raw, S* energies) {
  pack.at(Index(blockIdx.x), Index(threadIdx.x), x, q, conf, graph, grad_x, grad_tangent, grad_raw, energies);
}

// The kernels of the list's Elements: one per Element, then the whole pack.
template <class S, class I, class... Es>
auto element_kernels(cd::ElementPack<Es...>*) {
  return std::make_tuple(&elements_usage<S, I, cd::ElementPack<Es>>..., &elements_usage<S, I, cd::ElementPack<Es...>>);
}
template <class S, class I>
auto list_kernels() {
  static_assert(cd::ListElements<S, I>::size > 0, "the term list has no Element: nothing is checked here");
  return element_kernels<S, I>(static_cast<cd::ListElements<S, I>*>(nullptr));
}

// Taking the kernels' addresses instantiates them (device code included).
auto float_kernels = list_kernels<float, std::int32_t>();
auto double_kernels = list_kernels<double, std::int64_t>();

}  // namespace smg_device_usage_term_elements
