# examples/torch/fit_nodes.py on a tiny synthetic case written in the layout of
# `smg_trainer --export-case` (so that the script is exercised without the trainer).
import importlib.util
import json
import os

import numpy as np
import torch

import smg_torch as smg

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_spec = importlib.util.spec_from_file_location("fit_nodes", os.path.join(ROOT, "examples", "torch", "fit_nodes.py"))
fit_nodes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fit_nodes)


def write_case(d, T=8, N=40, K=6, seed=0):
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
              "alpha": 0.6, "gaps": [1, 2, 4], "gap_weights": [1.0, 1.0, 1.0], "kappa_m": 2.5,
              "kappa_r": 2.5, "lambda_m": 1.0, "lambda_r": 1.0, "confidence_eps": 1e-4,
              "iterations": 500, "lr_position": 2e-3, "lr_position_final": 5e-4, "lr_rotation": 1e-2,
              "lr_rotation_final": 1e-3, "confidence_every": 5, "extent": 0.5}
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
