# examples/torch/fit_nodes.py on a tiny synthetic case written in the layout of
# `smg_trainer --export-case` (so that the script is exercised without the trainer).
import importlib.util
import json
import os

import numpy as np
import pytest
import torch

import smg_torch as smg

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_spec = importlib.util.spec_from_file_location("fit_nodes", os.path.join(ROOT, "examples", "torch", "fit_nodes.py"))
fit_nodes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fit_nodes)


def write_case(d, T=8, N=40, K=6, seed=0, **config_changes):
    """A case in the export's layout; config_changes update case.json (None removes a key)."""
    g = torch.Generator().manual_seed(seed)
    x0 = torch.rand(N, 3, generator=g, dtype=torch.float64) * 0.3
    t = torch.linspace(0, 1, T, dtype=torch.float64)[:, None]
    ang = 0.6 * t  # a rigid rotation about z plus a translation
    c, s = torch.cos(ang)[:, :, None], torch.sin(ang)[:, :, None]
    gt = torch.cat([c * x0[None, :, :1] - s * x0[None, :, 1:2], s * x0[None, :, :1] + c * x0[None, :, 1:2],
                    x0[None, :, 2:].expand(T, N, 1)], -1) + torch.tensor([0.1, 0.0, 0.0]) * t[:, :, None]
    lifted = gt + 0.01 * torch.randn(T, N, 3, generator=g, dtype=torch.float64)
    vis = (torch.rand(T, N, generator=g) > 0.2).to(torch.uint8)
    graph = smg.build_graph(gt, k=K, gate=False)
    quats = torch.zeros(T, N, 4, dtype=torch.float64)
    quats[..., 0] = 1
    for name, a in {"lifted": lifted, "visibility": vis, "gt_positions": gt, "quats": quats,
                    "graph_indices": graph.indices.long(), "graph_weights": graph.weights.double()}.items():
        np.save(os.path.join(d, name + ".npy"), a.numpy())
    config = {"T": T, "N": N, "K": K, "variant": "full", "rigidity": "carap", "lrm": True,
              "w_data": 1.0, "data_huber": 0.02, "w_rigidity": 0.1, "w_lrm": 0.1, "lrm_huber": 0.01,
              "w_accel": 0.0, "alpha": 0.6, "gaps": [1, 2, 4], "gap_weights": [1.0, 1.0, 1.0], "kappa_m": 2.5,
              "kappa_r": 2.5, "lambda_m": 1.0, "lambda_r": 1.0, "confidence_eps": 1e-4,
              "iterations": 500, "lr_position": 2e-3, "lr_position_final": 5e-4, "lr_rotation": 1e-2,
              "lr_rotation_final": 1e-3, "confidence_every": 5, "extent": 0.5}
    for key, value in config_changes.items():
        if value is None:
            config.pop(key, None)
        else:
            config[key] = value
    with open(os.path.join(d, "case.json"), "w", encoding="utf-8") as f:
        json.dump(config, f)


def test_fit_nodes_main_decreases_the_loss(tmp_path, capsys):
    write_case(str(tmp_path))
    r = fit_nodes.main([str(tmp_path), "--iters", "40", "--threads", "1", "--quiet"])
    out = capsys.readouterr().out
    assert "node EPE lifted" in out and "time per iteration" in out
    assert r["iterations"] == 40 and len(r["losses"]) == 40
    assert all(np.isfinite(r["losses"]))
    assert r["losses"][-1] < 0.9 * r["losses"][0]
    assert r["loss_final"] < r["losses"][0]
    assert np.isfinite(r["epe_before"]) and np.isfinite(r["epe_after"])
    assert r["x"].shape == (8, 40, 3) and r["q"].shape == (8, 40, 4)
    assert torch.allclose(r["q"].norm(dim=-1), torch.ones(8, 40, dtype=torch.float64))


def test_fit_nodes_rejects_inconsistent_shapes(tmp_path):
    write_case(str(tmp_path))
    np.save(os.path.join(str(tmp_path), "quats.npy"), np.zeros((3, 3, 4)))
    try:
        fit_nodes.load_case(str(tmp_path))
    except ValueError as e:
        assert "inconsistent shapes" in str(e)
    else:
        raise AssertionError("expected ValueError")


def accel_reference(x, w_accel):
    """The trainer's smoothness term (nodes.cpp, NodeObjective: AccelOptions weight
    w_accel / (T N), Normalization::sum, unweighted accelerations) in plain torch."""
    T, N = x.shape[:2]
    a = x[2:] - 2 * x[1:-1] + x[:-2]
    return w_accel / (T * N) * (a * a).sum()


def rel(a, b):
    a, b = torch.as_tensor(a, dtype=torch.float64), torch.as_tensor(b, dtype=torch.float64)
    return float((a - b).abs().max() / b.abs().max().clamp_min(1e-300))


def test_fit_nodes_fits_the_smoothness_term(tmp_path):
    w_accel = 0.5
    write_case(str(tmp_path), w_accel=w_accel)
    case = fit_nodes.load_case(str(tmp_path))
    r = fit_nodes.fit(case, iters=30, threads=1, log=None)
    x = r["x"]
    assert x.dtype == torch.float64
    # The term at the fitted positions, as the loss computes it, against plain torch.
    loss_fn = fit_nodes.Stage1Loss(case)
    loss_fn.update_confidences(x)
    xs = x.clone().requires_grad_(True)
    total, terms = loss_fn(xs, r["q"])
    xr = x.clone().requires_grad_(True)
    expected = accel_reference(xr, w_accel)
    assert float(expected) > 0
    assert rel(terms["accel"], expected) < 1e-9
    # Its gradient too (the term's alone: the other terms are differentiated separately).
    (gx,) = torch.autograd.grad(terms["accel"], xs)
    (gr,) = torch.autograd.grad(expected, xr)
    assert rel(gx, gr) < 1e-9
    # The loss includes it: the final loss is the other terms plus the smoothness.
    assert rel(total, sum(v for k, v in terms.items() if k != "accel") + expected) < 1e-9
    assert rel(r["loss_final"], float(total)) < 1e-12
    off = dict(case, config=dict(case["config"], w_accel=0.0))
    loss_off = fit_nodes.Stage1Loss(off)
    loss_off.update_confidences(x)
    with torch.no_grad():
        total_off, terms_off = loss_off(x, r["q"])
    assert "accel" not in terms_off
    assert rel(r["loss_final"] - float(total_off), expected) < 1e-9
    # And the fit follows it: smoother trajectories than the same fit without the term.
    r_off = fit_nodes.fit(off, iters=30, threads=1, log=None)
    assert float(accel_reference(x, 1.0)) < float(accel_reference(r_off["x"], 1.0))


def test_fit_nodes_w_accel_zero_is_the_fit_without_the_term(tmp_path):
    # w_accel = 0 (the trainer's default) and a case.json without the key fit identically.
    runs = []
    for name, w in (("zero", 0.0), ("absent", None)):
        d = tmp_path / name
        d.mkdir()
        write_case(str(d), w_accel=w)
        case = fit_nodes.load_case(str(d))
        assert ("w_accel" in case["config"]) == (w is not None)
        r = fit_nodes.fit(case, iters=20, threads=1, log=None)
        _, terms = fit_nodes.Stage1Loss(case)(r["x"], r["q"])
        assert set(terms) == {"data", "rigidity", "lrm"}
        runs.append(r)
    assert runs[0]["losses"] == runs[1]["losses"]
    assert torch.equal(runs[0]["x"], runs[1]["x"]) and torch.equal(runs[0]["q"], runs[1]["q"])


def test_fit_nodes_refuses_a_term_it_does_not_fit(tmp_path, capsys):
    write_case(str(tmp_path), w_velocity=0.3)
    with pytest.raises(SystemExit) as e:
        fit_nodes.main([str(tmp_path), "--iters", "2", "--quiet"])
    assert e.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "'w_velocity'" in lines[0] and "not implemented" in lines[0]
    with pytest.raises(fit_nodes.CaseError, match="'w_velocity'"):
        fit_nodes.load_case(str(tmp_path))


@pytest.mark.parametrize("changes, key", [
    ({"w_velocity": True}, "'w_velocity'"),     # not a number: refused even though it is not 0
    ({"w_accel": -0.1}, "'w_accel'"),           # a negative weight
    ({"w_accel": "0.1"}, "'w_accel'"),          # not a number
    ({"rigidity": "elastic"}, "'rigidity'"),    # a rigidity it does not fit
])
def test_fit_nodes_refuses_terms_it_cannot_fit_as_the_trainer(tmp_path, changes, key):
    write_case(str(tmp_path), **changes)
    with pytest.raises(fit_nodes.CaseError, match=key):
        fit_nodes.load_case(str(tmp_path))


def test_fit_nodes_accepts_an_unknown_term_at_weight_zero(tmp_path):
    # A term the trainer records with weight 0 is off there too: nothing to fit.
    write_case(str(tmp_path), w_velocity=0.0)
    r = fit_nodes.fit(fit_nodes.load_case(str(tmp_path)), iters=2, threads=1, log=None)
    assert len(r["losses"]) == 2
