# The benchmark scripts' own code (bench/torch): the scaling table's KNN graph is exact, and the
# new paths (--scaling, the torch.compile peer, bench_cuda.py's options) run. Small sizes: a few
# seconds.
import json
import os
import subprocess
import sys

import torch

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BENCH = os.path.join(ROOT, "bench", "torch")
sys.path.insert(0, BENCH)

import bench_torch  # noqa: E402


def brute_knn(p, K):
    d = torch.cdist(p, p)
    d.fill_diagonal_(float("inf"))
    return d.topk(K, largest=False).indices


def test_grid_knn_is_exact():
    g = torch.Generator().manual_seed(5)
    # the benchmark's slab, and a cloud with empty regions (a few rows need the fallback)
    slab = torch.rand(3000, 3, generator=g, dtype=torch.float64) * torch.tensor([4.0, 4.0, 1.0], dtype=torch.float64)
    blobs = torch.cat([torch.randn(800, 3, generator=g, dtype=torch.float64) * 0.1,
                       torch.randn(40, 3, generator=g, dtype=torch.float64) + 5.0])
    for p in (slab, blobs):
        got = bench_torch.grid_knn(p, 16, chunk=512)
        want = brute_knn(p, 16)
        assert torch.equal(got.sort(1).values, want.sort(1).values)
        # nearest first, as build_graph orders them
        d = (p[got] - p[:, None]).norm(dim=-1)
        assert bool((d[:, 1:] >= d[:, :-1]).all())


def test_carap_terms_counts_valid_edges():
    idx = torch.tensor([[1, 2, -1], [0, -1, -1], [0, 1, -1]])
    # 5 valid edges; gaps 1, 2, 4 at T = 5: (4 + 3 + 1) pairs of frames
    assert bench_torch.carap_terms(idx, 5) == 5 * 8
    assert bench_torch.carap_terms(idx, 3) == 5 * (2 + 1)


def _run(args, tmp_path):
    env = dict(os.environ, PYTHONPATH=os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable] + args, cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=120)


def test_scaling_quick_runs(tmp_path):
    out = tmp_path / "scaling.json"
    r = _run([os.path.join(BENCH, "bench_torch.py"), "--quick", "--scaling", "--repeat", "1",
              "--skip-seconds", "1e-6", "--json", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    rows = json.loads(out.read_text())["benchmarks"]
    assert len(rows) == len(bench_torch.SCALING_QUICK)
    first, later = rows[0], rows[1:]
    assert first["real_time"] > 0 and first["pytorch_ms"] > 0 and first["terms"] > 0
    # every later eager peer is predicted over the (tiny) time limit: skipped, no number
    for b in later:
        assert b["real_time"] > 0
        assert b["pytorch_note"].startswith("skipped: predicted")
        assert b["pytorch_ms"] != b["pytorch_ms"]  # NaN
    for b in rows:
        if hasattr(torch, "compile"):
            # the first size runs; later ones are predicted over the limit as the eager peer's
            # (torch 2.x on a GPU machine, 2026-11-28: compile_ms NaN there, with the note)
            assert (b["compile_ms"] > 0 and b["compile_time_s"] > 0) if b is first else \
                (b["compile_ms"] > 0 or b["compile_note"].startswith("skipped: predicted"))
        else:
            assert b["compile_note"] == f"torch.compile: not available in torch {torch.__version__}"
            assert b["compile_ms"] != b["compile_ms"]
    assert "| N x T |" in r.stdout


def test_bench_compat_quick_runs(tmp_path):
    out = tmp_path / "compat.json"
    r = _run([os.path.join(BENCH, "bench_compat.py"), "--quick", "--json", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    rows = json.loads(out.read_text())["rows"]
    # SoM x2, MoSca x2, D3DGS, DreamScene4D, Marbles x2, DynOMo, SC-GS
    assert [row["peer"] for row in rows] == ["smg", "torch"] * 10
    for row in rows:
        assert row["seconds"] > 0 and row["rel_diff"] < 1e-5
    assert "| case | shape | peer |" in r.stdout


def test_bench_compat_isa_ab_runs_the_baseline_by_turns(tmp_path):
    out = tmp_path / "compat.json"
    r = _run([os.path.join(BENCH, "bench_compat.py"), "--quick", "--isa-ab", "--cases", "MoSca vel", "--json",
              str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert [row["peer"] for row in d["rows"]] == ["smg", "smg base", "torch"]
    assert d["isa"] in ("base", "avx2+fma")
    assert all(row["seconds"] > 0 for row in d["rows"])


def test_bench_knn_quick_runs(tmp_path):
    """bench/torch/bench_knn.py --quick: every peer present here runs, and the exact ones (the
    tree tools, on float64 points) return smg's rows."""
    out = tmp_path / "knn.json"
    r = _run([os.path.join(BENCH, "bench_knn.py"), "--quick", "--json", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    rows = json.loads(out.read_text())["rows"]
    assert rows[0]["method"].startswith("smg_torch.knn_points float32") and rows[0]["ms"] > 0
    for row in rows:
        if row["method"].startswith(("scipy cKDTree", "Open3D")) and row["ms"] is not None:
            assert row["same"] is True
        if row["method"].startswith("torch cdist"):
            assert row["same"] > 0.99  # cdist's rounding may swap near-ties
    assert "| method | ms |" in r.stdout


def test_bench_cuda_options(tmp_path):
    r = _run([os.path.join(BENCH, "bench_cuda.py"), "--help"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "--scaling" in r.stdout


def test_bench_cuda_fails_without_cuda_operators(tmp_path):
    # Nothing to measure must fail loudly (issue 36): exit 1 with one "bench_cuda: error:" line.
    import smg_torch
    if smg_torch.has_cuda and torch.cuda.is_available():
        import pytest
        pytest.skip("this smg_torch has its CUDA operators and a device: bench_cuda.py would run")
    r = _run([os.path.join(BENCH, "bench_cuda.py"), "--quick", "--repeat", "1"], tmp_path)
    assert r.returncode == 1, (r.returncode, r.stdout, r.stderr)
    lines = [l for l in r.stderr.splitlines() if l.startswith("bench_cuda: error:")]
    assert len(lines) == 1, r.stderr
    assert ("built without its CUDA operators" in lines[0]) == (not smg_torch.has_cuda), lines[0]
    assert "skipped" not in r.stdout
