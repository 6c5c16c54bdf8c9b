"""smg_torch.compat — the field's regularisers as their code computes them, through smg's
operators, so that a training script swaps one line (docs/compat.md).

    from smg_torch.compat import som_accel
    loss = som_accel(transls)          # Shape of Motion's compute_accel_loss(transls)

Covered so far: Shape of Motion's `compute_accel_loss` (flow3d/loss_utils.py), on 3-vectors.
"""
from __future__ import annotations

import torch

from . import REGULARIZER_DEFAULTS, _C, _scale, has_cuda, regularizers

__all__ = ["som_accel"]

# smg's smoothness (E21) with the unsquared norm (E22) and Normalization::mean, i.e. the mean of
# ‖a‖ over the (T − 2)·N terms: the accel term's options.
_SOM_ACCEL = dict(REGULARIZER_DEFAULTS["accel"], form="acceleration", penalty="norm",
                  confidence_weighted=False, normalize=True, weight=1.0)
# On CUDA tensors: the fused step with smoothness alone (no term reads the empty graph).
_OFF = dict(confidence=False, carap=False, arap=False, lrm=False)


class _AccelFunction(torch.autograd.Function):
    """smg::accel (the one-term operator) on CPU tensors x [T, N, 3]: the energy, and its gradient
    computed in the same pass when x requires grad (scaled by grad_output in backward)."""

    @staticmethod
    def forward(ctx, x, options):
        e, g = _C._accel(x.detach(), options, bool(ctx.needs_input_grad[0]))
        ctx.grad = g
        return e

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_output):
        return _scale(grad_output, ctx.grad), None


def som_accel(transls: torch.Tensor) -> torch.Tensor:
    """Shape of Motion's `compute_accel_loss(transls)`: the mean over every index but the last of
    the unsquared norm of the second difference along dim 1 (time),

        mean ‖2 x[:, t] − x[:, t−1] − x[:, t+1]‖,   t = 1 … T−2,

    which is smg's trajectory smoothness (E21) with penalty="norm" (E22) and normalize=True.
    transls: [K, T, 3] (the motion bases' translations, or [G, T, 3] tracks) or [K, T, ..., 3]
    (e.g. the trainer's [G, 3, B, 3] track neighbourhoods: time is dim 1, as upstream slices it;
    the dims after it are more trajectories), float32 or float64, CPU or CUDA (with a CUDA build),
    T >= 3 and no empty dim. Returns a 0-dim tensor of transls' dtype with autograd to transls;
    where a second difference is exactly 0 its gradient is exactly 0, as torch's norm backward
    gives. Shape of Motion's rotation bases ([K, T, 6]) are not covered: smg's smoothness is on
    3-vectors, and splitting a 6-vector in two is exact only for the squared form.

    On CPU tensors it calls smg::accel, the one-term operator; on CUDA tensors the fused step
    with smoothness alone (smg::cuda::regularizers, the same element).

    Memory, honestly: smg reads trajectories as [T][N][3], frame-major, and transls is
    trajectory-major, so one copy of transls in that layout is made (transls.movedim(1, 0) then
    a reshape to [T, N, 3], N = the product of the other dims; no copy when dim 0 has size 1),
    plus the gradient [T, N, 3] that smg writes in the same pass (returned to autograd as a view
    in transls' shape). No [..., T − 2, 3] intermediates: the differences, norms and their
    gradients are formed per element inside smg's loop. On CPU, smg's scratch is kept between
    calls (one workspace per thread and dtype, as a trainer keeps one; it only grows): at T = 3
    it is about 7 times the input (76 MiB for G·B = 320 000 float32 trajectories)."""
    if not isinstance(transls, torch.Tensor):
        raise ValueError(f"transls: expected a torch.Tensor, got {type(transls).__name__}")
    if transls.dim() < 3:
        raise ValueError(f"transls: expected shape [K, T, 3] or [K, T, ..., 3], got {list(transls.shape)}")
    if transls.shape[-1] != 3:
        raise ValueError(f"transls: the last dim must be 3 (smg's smoothness is on 3-vectors; Shape of "
                         f"Motion's 6-D rotation bases are not covered), got shape {list(transls.shape)}")
    if transls.dtype not in (torch.float32, torch.float64):
        raise ValueError(f"transls: dtype must be float32 or float64, got {transls.dtype}")
    if transls.device.type not in ("cpu", "cuda"):
        raise ValueError(f"transls: device must be cpu or cuda, got {transls.device}")
    if transls.is_cuda and not has_cuda:
        raise NotImplementedError("transls: a CUDA tensor, but smg_torch was built without its CUDA "
                                  "operators (smg_torch.has_cuda is False)")
    T = transls.shape[1]
    if T < 3:
        raise ValueError(f"transls: needs T >= 3 frames on dim 1 for a second difference, got shape "
                         f"{list(transls.shape)} (Shape of Motion's mean over no terms is NaN)")
    if transls.numel() == 0:
        raise ValueError(f"transls: has an empty dim, shape {list(transls.shape)} (Shape of Motion's "
                         "mean over no terms is NaN)")
    x = transls.movedim(1, 0).reshape(T, -1, 3)  # [T, N, 3]: a copy unless dim 0 has size 1
    if not x.is_cuda:
        return _AccelFunction.apply(x, _SOM_ACCEL)
    # CUDA: smg::cuda::regularizers runs the same element (AccelElement); an empty [N, 0] graph.
    n = x.shape[1]
    idx = torch.empty((n, 0), dtype=torch.int32, device=transls.device)
    w = torch.empty((n, 0), dtype=transls.dtype, device=transls.device)
    return regularizers(x, None, (idx, w), accel=_SOM_ACCEL, **_OFF).total
