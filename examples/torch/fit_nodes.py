#!/usr/bin/env python3
"""fit_nodes.py — stage 1 of the example trainer (docs/trainer.md) in PyTorch, on a case that
`smg_trainer --export-case DIR` wrote.

usage: PYTHONPATH=<build>/python /usr/bin/python3 examples/torch/fit_nodes.py CASE_DIR
           [--iters N] [--threads N] [--quiet]

The node trajectories x [T, N, 3] start from the lifted tracks (lifted.npy) and the raw node
quaternions q [T, N, 4] (w, x, y, z) from quats.npy; both are torch.optim.Adam parameters
(learning rates log-decayed from case.json's lr_* to lr_*_final, as the C++ stage 1 does). The
loss has the C++ stage 1's terms and normalisation (examples/trainer/nodes.hpp):

    w_data / (T N)           * sum over visible (t, i) of Huber(|x_i^t - y_i^t|, data_huber)   (PyTorch)
  + w_rigidity / (N sum_d gamma_d (T - d)) * C-ARAP(x, q; c)   (smg_torch.carap; arap / none per variant)
  + w_lrm / (T N)          * LRM(x; c)                          (smg_torch.lrm, if the variant has it)
  + w_accel / (T N)        * sum_{t,i} |x_i^{t+2} - 2 x_i^{t+1} + x_i^t|^2   (E21; smg_torch.regularizers'
                                                                 accel term, if w_accel > 0)

with the confidences c = smg_torch.node_confidences(x, graph, visibility) recomputed every
`confidence_every` iterations (constants in between). Prints node EPE (mean distance to
gt_positions.npy, metres) before and after and the time per iteration. Differences from the C++
stage 1: Adam steps the raw quaternions (renormalised after each step) instead of right-tangent
rotation steps.

A case it cannot fit as the trainer would is refused, with one line on stderr naming the key and
exit code 2, before any work: a stage-1 term weight (a `w_*` key of case.json) other than w_data,
w_rigidity, w_lrm and w_accel unless its value is 0 (that term is then off, as in the trainer), a
negative or non-numeric weight, or a `rigidity` other than carap, arap and none.
"""
import argparse
import json
import math
import os
import sys
import time

# Before torch starts its OpenMP pool (as bench/torch/bench_torch.py): spinning OpenMP threads
# on a shared, loaded machine make 2-thread runs erratic.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

# This folder holds the package's sources (examples/torch/smg_torch, without the compiled _C):
# import the built package from PYTHONPATH instead.
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]

import smg_torch as smg  # noqa: E402

CASE_FILES = ("lifted.npy", "visibility.npy", "gt_positions.npy", "quats.npy", "graph_indices.npy",
              "graph_weights.npy")

#: The stage-1 terms' weights in case.json that Stage1Loss fits (the trainer's NodeLossOptions).
TERM_WEIGHTS = ("w_data", "w_rigidity", "w_lrm", "w_accel")
RIGIDITIES = ("carap", "arap", "none")


class CaseError(ValueError):
    """A case this script cannot fit as the trainer's stage 1 would; main prints it as one line."""


def check_terms(config, where="case.json"):
    """Refuses (CaseError naming the key) a case.json with a stage-1 term this script does not
    fit: a weight key `w_*` other than TERM_WEIGHTS with a value other than 0, a term weight that is
    negative or not a number, or an unknown rigidity."""
    for key, value in config.items():
        if not key.startswith("w_"):
            continue
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if key not in TERM_WEIGHTS:
            if not (numeric and value == 0):
                raise CaseError(f"{where}: stage-1 term {key!r} = {value!r} is not implemented by fit_nodes.py "
                                f"(it fits {', '.join(TERM_WEIGHTS)}); refusing the case")
        elif not numeric or value < 0:
            raise CaseError(f"{where}: {key!r} = {value!r} is not a weight >= 0; refusing the case")
    rigidity = config.get("rigidity", "carap")
    if rigidity not in RIGIDITIES:
        raise CaseError(f"{where}: 'rigidity' = {rigidity!r} is not implemented by fit_nodes.py "
                        f"(it fits {', '.join(RIGIDITIES)}); refusing the case")


def load_case(case_dir):
    """The exported stage-1 problem: a dict of tensors (float64, visibility uint8, indices
    int64) plus 'config' (case.json). CaseError for a case this script cannot fit (check_terms)
    or whose files' shapes disagree."""
    with open(os.path.join(case_dir, "case.json"), encoding="utf-8") as f:
        config = json.load(f)
    check_terms(config, os.path.join(case_dir, "case.json"))
    arrays = {name[:-4]: torch.from_numpy(np.load(os.path.join(case_dir, name))) for name in CASE_FILES}
    T, N = arrays["lifted"].shape[:2]
    if arrays["visibility"].shape != (T, N) or arrays["gt_positions"].shape != (T, N, 3) or \
            arrays["quats"].shape != (T, N, 4) or arrays["graph_indices"].shape[0] != N or \
            arrays["graph_weights"].shape != arrays["graph_indices"].shape:
        raise CaseError(f"{case_dir}: inconsistent shapes in the case files")
    arrays["lifted"] = arrays["lifted"].double()
    arrays["gt_positions"] = arrays["gt_positions"].double()
    arrays["quats"] = arrays["quats"].double()
    arrays["graph_weights"] = arrays["graph_weights"].double()
    arrays["graph_indices"] = arrays["graph_indices"].long()
    arrays["visibility"] = arrays["visibility"].to(torch.uint8)
    arrays["config"] = config
    return arrays


def node_epe(x, truth):
    """Mean Euclidean distance to the ground truth over every node and frame (metres)."""
    return float((x.detach() - truth).norm(dim=-1).mean())


def _huber_of_distance(sq, delta):
    # Huber of |r| from |r|^2 without sqrt(0) (whose gradient is NaN) on the quadratic branch.
    far = delta * (torch.sqrt(sq.clamp_min(delta * delta)) - 0.5 * delta)
    return torch.where(sq <= delta * delta, 0.5 * sq, far)


class Stage1Loss:
    """The C++ stage 1's energy (examples/trainer/nodes.cpp) on torch tensors."""

    def __init__(self, case):
        c = case["config"]
        check_terms(c)
        self.c = c
        self.observed = case["lifted"].clone()
        self.visible = case["visibility"].to(torch.float64)
        self.visibility = case["visibility"]
        self.graph = smg.Graph(case["graph_indices"], case["graph_weights"])
        T, N = self.observed.shape[:2]
        self.T, self.N = T, N
        per_node_frame = 1.0 / (T * N)
        self.w_data = c["w_data"] * per_node_frame
        gaps = [int(d) for d in c["gaps"]]
        gap_w = [float(w) for w in c.get("gap_weights", [1.0] * len(gaps))]
        self.gaps, self.gap_weights = gaps, gap_w
        frames_gaps = sum(w * max(0, T - d) for d, w in zip(gaps, gap_w))
        self.w_rig = c["w_rigidity"] / (N * frames_gaps) if frames_gaps > 0 else 0.0
        self.w_lrm = c["w_lrm"] * per_node_frame
        # Smoothness (E21) as the trainer's NodeObjective adds it: weight w_accel / (T N) on the sum
        # (not the mean) of the unweighted squared accelerations, only when w_accel > 0. Through
        # smg_torch.regularizers with every other term off (smg::accel's term; no quaternions).
        self.w_accel = float(c.get("w_accel", 0.0)) * per_node_frame
        self.accel_terms = {t: False for t in smg.REGULARIZER_TERMS if t != "accel"}
        self.accel_terms["accel"] = {"form": "acceleration", "confidence_weighted": False,
                                     "normalize": False, "weight": self.w_accel}
        self.rigidity = c.get("rigidity", "carap")
        self.lrm_on = bool(c.get("lrm", True))
        self.confidence = None

    def uses_confidence(self):
        return self.rigidity == "carap" or self.lrm_on

    def update_confidences(self, x):
        if self.uses_confidence():
            c = self.c
            self.confidence = smg.node_confidences(
                x.detach(), self.graph, self.visibility, kappa_m=c["kappa_m"], kappa_r=c["kappa_r"],
                lambda_m=c["lambda_m"], lambda_r=c["lambda_r"], eps=c["confidence_eps"])

    def __call__(self, x, q):
        c = self.c
        sq = ((x - self.observed) ** 2).sum(-1)
        data = self.w_data * (self.visible * _huber_of_distance(sq, c["data_huber"])).sum()
        terms = {"data": data}
        if self.rigidity == "carap":
            terms["rigidity"] = self.w_rig * smg.carap(x, q, self.graph, self.confidence, alpha=c["alpha"],
                                                       gaps=self.gaps, gap_weights=self.gap_weights)
        elif self.rigidity == "arap":
            terms["rigidity"] = self.w_rig * smg.arap(x, q, self.graph, gaps=self.gaps,
                                                      gap_weights=self.gap_weights)
        if self.lrm_on:
            terms["lrm"] = self.w_lrm * smg.lrm(x, self.graph, self.confidence, alpha=c["alpha"],
                                                huber_delta=c["lrm_huber"])
        if self.w_accel > 0:
            terms["accel"] = smg.regularizers(x, None, self.graph, None, **self.accel_terms).total
        return sum(terms.values()), terms


def log_lerp(a, b, p):
    return a * math.pow(b / a, p) if a > 0 and b > 0 else a + (b - a) * p


def fit(case, iters=None, threads=None, log=print, log_every=50):
    """Runs the PyTorch stage 1; returns a dict with epe_before, epe_after, ms_per_iteration,
    losses (one per iteration, the loss the step was taken on) and the fitted x, q."""
    if threads:
        torch.set_num_threads(int(threads))
    c = case["config"]
    iters = int(c["iterations"] if iters is None else iters)
    loss_fn = Stage1Loss(case)
    x = case["lifted"].clone().requires_grad_(True)
    q = case["quats"].clone().requires_grad_(True)
    rotations = loss_fn.rigidity != "none"
    groups = [{"params": [x], "lr": c["lr_position"]}]
    if rotations:
        groups.append({"params": [q], "lr": c["lr_rotation"]})
    opt = torch.optim.Adam(groups)
    truth = case["gt_positions"]
    epe_before = node_epe(x, truth)
    every = int(c.get("confidence_every", 20))
    losses = []
    t0 = time.perf_counter()
    loss_fn.update_confidences(x)
    for it in range(iters):
        if every > 0 and it > 0 and it % every == 0:
            loss_fn.update_confidences(x)
        p = it / (iters - 1) if iters > 1 else 1.0
        opt.param_groups[0]["lr"] = log_lerp(c["lr_position"], c["lr_position_final"], p)
        if rotations:
            opt.param_groups[1]["lr"] = log_lerp(c["lr_rotation"], c["lr_rotation_final"], p)
        opt.zero_grad(set_to_none=True)
        loss, terms = loss_fn(x, q)
        loss.backward()
        opt.step()
        if rotations:
            with torch.no_grad():
                q /= q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        losses.append(float(loss))
        if log and log_every > 0 and (it % log_every == 0 or it + 1 == iters):
            parts = "  ".join(f"{k} {float(v):.3e}" for k, v in terms.items())
            log(f"it {it + 1:4d}/{iters}  loss {float(loss):.4e}  ({parts})")
    seconds = time.perf_counter() - t0
    loss_fn.update_confidences(x)
    with torch.no_grad():
        final, _ = loss_fn(x, q)
    return {"epe_before": epe_before, "epe_after": node_epe(x, truth), "iterations": iters,
            "seconds": seconds, "ms_per_iteration": 1e3 * seconds / max(1, iters),
            "losses": losses, "loss_final": float(final), "threads": torch.get_num_threads(),
            "x": x.detach(), "q": q.detach()}


def main(argv=None):
    ap = argparse.ArgumentParser(description="PyTorch stage 1 (smg_torch C-ARAP + LRM + smoothness) on an "
                                             "exported case")
    ap.add_argument("case_dir", help="folder written by smg_trainer --export-case")
    ap.add_argument("--iters", type=int, default=None, help="iterations (default: case.json's)")
    ap.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")
    a = ap.parse_args(argv)
    if a.iters is not None and a.iters < 0:
        ap.error("--iters must be >= 0")
    if a.threads is not None and a.threads < 1:
        ap.error("--threads must be >= 1")
    try:
        case = load_case(a.case_dir)
    except CaseError as e:
        print(f"fit_nodes.py: {e}", file=sys.stderr)
        raise SystemExit(2)
    c = case["config"]
    log = None if a.quiet else (lambda s: print(s, file=sys.stderr))
    r = fit(case, a.iters, a.threads, log=log)
    print(f"case {a.case_dir}: variant {c.get('variant')}, T={c['T']} N={c['N']} K={c['K']}, "
          f"{r['iterations']} iterations, {r['threads']} threads")
    print(f"node EPE lifted {r['epe_before']:.4f} m -> fitted {r['epe_after']:.4f} m")
    print(f"time per iteration {r['ms_per_iteration']:.2f} ms ({r['seconds']:.2f} s in all)")
    return r


if __name__ == "__main__":
    main()
