#!/usr/bin/env python3
"""smg_torch.knn_points (exact point KNN, docs/math/graph.md (G15)) against the tools the field's
codebases build their neighbour tables with, on the CPU: best of --repeat calls, each building
its index and querying every point (the table a trainer builds).

usage: PYTHONPATH=<build>/python /usr/bin/python3 bench/torch/bench_knn.py [--n 100000] [--k 20]
           [--repeat 5] [--threads 2] [--quick] [--json FILE]

Points: --n uniform in a unit cube (float32, as the Gaussians' means), K = --k, self included
(the cKDTree / frnn convention; Open3D's loop asks K + 1 and drops self). Peers, each only where
installed (Debian: python3-scipy, python3-open3d):
- scipy's cKDTree (DreamScene4D's precompute_nn): build with leafsize=100 + query(k), workers=1
  (upstream's call) and workers=--threads;
- torch cdist + topk in row chunks of 1024 (the exact brute force a PyTorch user writes; chunked,
  as all [N, N] distances would need N² floats);
- Dynamic 3D Gaussians' o3d_knn (helpers.py): Open3D's KDTreeFlann, one search_knn_vector_3d per
  point in a Python loop (timed once, it takes seconds);
- smg_torch.knn_points at torch.set_num_threads(--threads).
Every peer's indices are checked against smg's rows (exact: float64 points for the tree tools,
which compute in float64; ties do not occur in random data); "same" says whether they agree.
--quick: N = 10 000, 2 repeats (a smoke run).
"""
import argparse
import json
import os
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

import smg_torch  # noqa: E402


def best(f, repeat):
    out, t = None, float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        t = min(t, time.perf_counter() - t0)
    return t * 1e3, out


def cdist_topk(p, K, chunk=1024):
    d2s, idxs = [], []
    for b in range(0, p.shape[0], chunk):
        d = torch.cdist(p[b:b + chunk], p)  # Euclidean; squared below
        v, i = torch.topk(d, K, dim=1, largest=False, sorted=True)
        d2s.append(v * v)
        idxs.append(i)
    return torch.cat(d2s), torch.cat(idxs)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=100000)
    ap.add_argument("--k", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    if a.quick:
        a.n, a.repeat = 10000, 2
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    p = torch.rand(a.n, 3, dtype=torch.float32)
    p64 = p.double()
    rows = []

    t, (d2, idx) = best(lambda: smg_torch.knn_points(p, a.k), a.repeat)
    rows.append(dict(method=f"smg_torch.knn_points float32 ({a.threads} threads)", ms=t, same=True))
    t, (d2d, idxd) = best(lambda: smg_torch.knn_points(p64, a.k), a.repeat)
    rows.append(dict(method=f"smg_torch.knn_points float64 ({a.threads} threads)", ms=t, same=True))

    try:
        from scipy.spatial import cKDTree
        x = p.numpy()
        for workers in sorted({1, a.threads}):
            def run(w=workers):
                return cKDTree(x, leafsize=100).query(x, k=a.k, workers=w)
            t, (_, i) = best(run, a.repeat)
            rows.append(dict(method=f"scipy cKDTree leafsize=100, query workers={workers}", ms=t,
                             same=bool((torch.from_numpy(i) == idxd).all())))
    except ImportError:
        rows.append(dict(method="scipy cKDTree", ms=None, same=None, note="scipy not installed"))

    t, (_, i) = best(lambda: cdist_topk(p, a.k), max(1, min(a.repeat, 2)))
    rows.append(dict(method="torch cdist + topk (chunks of 1024 rows)", ms=t,
                     same=float((i == idx).float().mean())))

    try:
        import numpy as np
        import open3d as o3d

        def o3d_knn():
            pcd = o3d.geometry.PointCloud()
            pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(p64.numpy()))
            tree = o3d.geometry.KDTreeFlann(pcd)
            out = []
            for q in pcd.points:
                _, i, _ = tree.search_knn_vector_3d(q, a.k)
                out.append(i)
            return np.array(out)
        t, i = best(o3d_knn, 1)
        rows.append(dict(method="Open3D KDTreeFlann, a Python loop of search_knn_vector_3d (D3DGS o3d_knn)",
                         ms=t, same=bool((torch.from_numpy(i).long() == idxd).all())))
    except ImportError:
        rows.append(dict(method="Open3D", ms=None, same=None, note="open3d not installed"))

    smg_ms = rows[0]["ms"]
    print(f"knn: N = {a.n}, K = {a.k}, float32 points, {a.threads} threads, best of {a.repeat}")
    print("| method | ms | smg float32 is x faster | same rows |")
    print("|---|---|---|---|")
    for r in rows:
        ms = "-" if r["ms"] is None else f"{r['ms']:.1f}"
        ratio = "-" if r["ms"] is None else f"{r['ms'] / smg_ms:.2f}"
        same = r.get("note", r["same"])
        print(f"| {r['method']} | {ms} | {ratio} | {same} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(n=a.n, k=a.k, threads=a.threads, repeat=a.repeat, rows=rows), f, indent=1)


if __name__ == "__main__":
    main()
