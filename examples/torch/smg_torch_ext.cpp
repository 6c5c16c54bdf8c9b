// examples/torch/smg_torch_ext.cpp — the compiled module smg_torch._C (docs: README "From
// PyTorch"). The Python package smg_torch wraps these functions in torch.autograd.Function.
#include <torch/python.h>

#include "smg/core/version.hpp"
#include "smg_torch_common.hpp"

PYBIND11_MODULE(_C, m) {
  m.doc() = "smg_torch._C: smg's operators over CPU tensors (use the smg_torch package)";
  // smg's parallel loops run on torch's intra-op pool; each call asks for at::get_num_threads().
  smg::set_executor({&smg_torch::torch_run, nullptr});
  m.attr("version") = SMG_VERSION_STRING;
  smg_torch::register_energy(m);
#ifdef SMG_TORCH_SKIN
  smg_torch::register_skin(m);
#endif
#ifdef SMG_TORCH_SPLAT
  smg_torch::register_splat(m);
#endif
#ifdef SMG_TORCH_GRAPH
  smg_torch::register_graph(m);
#endif
#ifdef SMG_TORCH_CUDA
  smg_torch::register_cuda(m);  // smg_torch_cuda.cu: cuda_* operators, has_cuda = True
#else
  m.attr("has_cuda") = false;
#endif
}
