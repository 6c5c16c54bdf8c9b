"""smg_torch errors: ValueError with the library's one-line message, inputs untouched."""
import pytest
import torch

import smg_torch as smg
from scenes import random_scene


def snapshot(*ts):
    return [t.clone() for t in ts]


def untouched(before, after):
    return all(a.dtype == b.dtype and a.shape == b.shape and
               (torch.equal(a, b) if not a.is_floating_point() else
                torch.allclose(a, b, rtol=0, atol=0, equal_nan=True)) for a, b in zip(before, after))


def energies(x, q, idx, w, c):
    g = (idx, w)
    return [lambda: smg.carap(x, q, g, c), lambda: smg.arap(x, q, g), lambda: smg.lrm(x, g, c),
            lambda: smg.node_confidences(x, g), lambda: smg.regularizers(x, q, g, arap=True).total]


CASES = {
    "positions shape": (lambda x, q, idx, w, c: (x[..., :2], q, idx, w, c), "positions", (0, 2, 3, 4)),
    "positions dtype": (lambda x, q, idx, w, c: ((x * 100).long(), q, idx, w, c), "positions", (0, 1, 2, 3, 4)),
    "quats shape": (lambda x, q, idx, w, c: (x, q[:, :5], idx, w, c), "quats", (0, 1, 4)),
    "quats dtype": (lambda x, q, idx, w, c: (x, q.float(), idx, w, c), "quats", (0, 1, 4)),
    "nan position": (lambda x, q, idx, w, c: (x.index_put((torch.tensor(2), torch.tensor(3)), torch.tensor([float("nan")] * 3)), q, idx, w, c), "positions", (0, 1, 2, 3, 4)),
    "inf quaternion": (lambda x, q, idx, w, c: (x, q.index_put((torch.tensor(1), torch.tensor(1)), torch.tensor([float("inf")] * 4)), idx, w, c), "quats", (0, 1, 4)),
    "zero quaternion": (lambda x, q, idx, w, c: (x, q.index_put((torch.tensor(1), torch.tensor(4)), torch.zeros(4)), idx, w, c), "zero quaternion", (0, 1, 4)),
    "index out of range": (lambda x, q, idx, w, c: (x, q, idx.index_put((torch.tensor(2), torch.tensor(1)), torch.tensor(99)), w, c), "out of range", (0, 1, 2, 3, 4)),
    "index dtype": (lambda x, q, idx, w, c: (x, q, idx.double(), w, c), "graph.indices", (0, 1, 2, 3, 4)),
    "weights shape": (lambda x, q, idx, w, c: (x, q, idx, w[:, :2], c), "graph.weights", (0, 1, 2, 3, 4)),
    "negative weight": (lambda x, q, idx, w, c: (x, q, idx, -w, c), "weight", (0, 1, 2, 3, 4)),
    "confidence shape": (lambda x, q, idx, w, c: (x, q, idx, w, c[:3]), "confidence", (0, 2)),
    "confidence > 1": (lambda x, q, idx, w, c: (x, q, idx, w, c + 1.5), "confidence", (0, 2)),
}


@pytest.mark.parametrize("name", list(CASES))
def test_value_errors_leave_inputs_untouched(name):
    make, needle, which = CASES[name]
    x, q, idx, w, c = random_scene()
    bx, bq, bidx, bw, bc = make(x, q, idx, w, c)
    args = [t.requires_grad_() if t.is_floating_point() and t is not bidx and t is not bw and t is not bc else t
            for t in (bx, bq, bidx, bw, bc)]
    before = snapshot(*args)
    fns = energies(*args)
    for k in which:
        with pytest.raises(ValueError) as info:
            fns[k]()
        msg = str(info.value)
        assert needle in msg and "\n" not in msg, msg
        assert "rotations" not in msg, msg  # the library's name for the caller's quats
    assert untouched(before, args)
    for t in args:
        assert t.grad is None


def test_option_errors():
    x, q, idx, w, c = random_scene()
    g = (idx, w)
    bad = [lambda: smg.carap(x, q, g, c, alpha=1.5), lambda: smg.carap(x, q, g, gaps=()),
           lambda: smg.carap(x, q, g, gaps=(1, 2), gap_weights=(1.0,)),
           lambda: smg.arap(x, q, g, gaps=(0,)), lambda: smg.arap(x, q, g, lambda_c=-1),
           lambda: smg.lrm(x, g, huber_delta=0), lambda: smg.node_confidences(x, g, kappa_m=0),
           lambda: smg.node_confidences(x, g, eps=-1), lambda: smg.carap(x, q, "graph"),
           lambda: smg.node_confidences(x, g, visibility=torch.ones(3, 3))]
    for f in bad:
        with pytest.raises(ValueError):
            f()


# regularizers: a term's option errors name the term and the option, in one line.
def test_regularizers_option_errors():
    x, q, idx, w, c = random_scene()
    g = (idx, w)
    cases = {"carap.alpha:": lambda: smg.regularizers(x, q, g, carap=dict(alpha=1.5)),
             "arap.gaps[0]:": lambda: smg.regularizers(x, q, g, arap=dict(gaps=(0,))),
             "lrm.huber_delta:": lambda: smg.regularizers(x, q, g, lrm=dict(huber_delta=0)),
             "accel.weight:": lambda: smg.regularizers(x, q, g, accel=dict(weight=-1)),
             "accel.form:": lambda: smg.regularizers(x, q, g, accel=dict(form="jerk")),
             "accel.penalty: must be 'squared' or 'norm' or 'sqrt_weighted', got 'cube'":
                 lambda: smg.regularizers(x, q, g, accel=dict(penalty="cube")),
             "accel.penalty_eps: must be finite and > 0, got 0":
                 lambda: smg.regularizers(x, q, g, accel=dict(penalty="sqrt_weighted", penalty_eps=0)),
             "confidence.kappa_m:": lambda: smg.regularizers(x, q, g, confidence=dict(kappa_m=0)),
             "carap: unknown option": lambda: smg.regularizers(x, q, g, carap=dict(beta=1)),
             "lrm: expected True, False or a dict": lambda: smg.regularizers(x, q, g, lrm=3),
             "quats: needed": lambda: smg.regularizers(x, None, g),
             "visibility": lambda: smg.regularizers(x, q, g, torch.ones(3, 3))}
    for needle, f in cases.items():
        with pytest.raises(ValueError) as info:
            f()
        msg = str(info.value)
        assert msg.startswith(needle) and "\n" not in msg, msg
    # Without carap and arap no quats are needed.
    r = smg.regularizers(x, None, g, carap=False)
    assert r.lrm > 0 and r.carap == 0


def test_cuda_not_implemented():
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device")
    x, q, idx, w, c = random_scene()
    if smg.has_cuda:  # the energies run on CUDA (tests/torch/test_cuda.py); the graph does not
        with pytest.raises(NotImplementedError, match="CPU only"):
            smg.build_graph(x.cuda())
        # The fused step runs on CUDA (tests/torch/test_cuda.py); mixed devices are refused.
        with pytest.raises(ValueError, match="graph.weights"):
            smg.regularizers(x.cuda(), q.cuda(), (idx.cuda(), w))
    else:
        with pytest.raises(NotImplementedError, match="built with CUDA"):
            smg.carap(x.cuda(), q.cuda(), (idx.cuda(), w.cuda()), c.cuda())
