#!/usr/bin/env python3
"""smg_torch against pure-PyTorch autograd (CPU): forward + backward, best of --repeat runs.

usage: PYTHONPATH=<build>/python /usr/bin/python3 bench/torch/bench_torch.py [--repeat 5]
           [--json bench/results/torch.json] [--quick] [--overhead-only]

Energies: N = 5000 nodes, T = 100 frames, K = 16, gaps 1,2,4, float32: node confidences + C-ARAP
+ LRM + ARAP, loss = sum of the three energies, backward to positions and raw quaternions, at 1
and 2 threads (torch.set_num_threads). The PyTorch baseline is tests/torch/torch_reference.py
(vectorised autograd implementations of docs/math/energy.md). DQB: 32768 points x 17 drivers
(K = 16), one query frame, against the autograd reference of docs/math/skin.md. Render: 100k
Gaussians at 320x240 through smg_torch; the dense pure-PyTorch reference
(tests/reference/gsplat_reference.py, every pixel against every Gaussian) is timed at a size it
fits in memory (2000 Gaussians, 160x120, float64 as the reference computes), where smg_torch
is timed too.
Overhead: smg_torch.carap and smg_torch.lrm forward + backward (autograd leaves, constant
confidences) against the bare C++ library call on the same tensors, timed in C++ with
std::chrono by smg_torch._library_seconds (zeroing the gradient buffers + the call), best of
--repeat runs taken interleaved, at 1 and 2 threads; overhead = binding / bare - 1.
Prints a markdown table; --json writes the same rows in Google Benchmark's JSON layout so that
bench/report.py puts them into docs/performance.md.
"""
import argparse
import datetime
import json
import math
import os
import sys
import time

# Before torch starts its OpenMP pool: on a shared, loaded machine, spinning OpenMP threads make
# every 2-thread timing (PyTorch's and smg's alike) erratic by 10-25x.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "tests", "torch"))
sys.path.insert(0, os.path.join(ROOT, "tests", "reference"))

import smg_torch as smg  # noqa: E402
import torch_reference as ref  # noqa: E402


def best_of(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def energy_scene(N, T, K, dtype=torch.float32):
    g = torch.Generator().manual_seed(1)
    # a bending, twisting slab: smooth motion plus noise
    x0 = torch.rand(N, 3, generator=g, dtype=torch.float64) * torch.tensor([4.0, 4.0, 1.0], dtype=torch.float64)
    t = torch.linspace(0, 1, T, dtype=torch.float64)[:, None, None]
    ang = 0.8 * t * x0[None, :, :1] / 4
    x = torch.cat([x0[None, :, :1] * torch.cos(ang) - x0[None, :, 2:] * torch.sin(ang),
                   x0[None, :, 1:2].expand(T, N, 1) + 0.2 * t,
                   x0[None, :, :1] * torch.sin(ang) + x0[None, :, 2:] * torch.cos(ang)], -1)
    x = x + 0.002 * torch.randn(T, N, 3, generator=g, dtype=torch.float64)
    q = torch.cat([torch.cos(ang / 2), torch.zeros(T, N, 1, dtype=torch.float64),
                   torch.sin(ang / 2), torch.zeros(T, N, 1, dtype=torch.float64)], -1)
    q = q + 0.01 * torch.randn(T, N, 4, generator=g, dtype=torch.float64)
    graph = smg.build_graph(x[:8], k=K, gate=False)
    return x.to(dtype), q.to(dtype), graph.indices, graph.weights.to(dtype)


def energies_smg(x, q, idx, w):
    xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
    c = smg.node_confidences(xs, (idx, w))
    e = smg.carap(xs, qs, (idx, w), c) + smg.lrm(xs, (idx, w), c) + smg.arap(xs, qs, (idx, w))
    e.backward()
    return float(e), xs.grad, qs.grad


def energies_torch(x, q, idx, w):
    xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
    c = ref.node_confidences(xs, idx, w)
    e = ref.carap(xs, qs, idx, w, c) + ref.lrm(xs, idx, w, c) + ref.arap(xs, qs, idx, w)
    e.backward()
    return float(e), xs.grad, qs.grad


def overhead_rows(x, q, idx, w, repeat):
    """(name, smg_torch seconds, bare C++ seconds) for C-ARAP and LRM at 1 and 2 threads."""
    rows = []
    N, T, K = x.shape[1], x.shape[0], idx.shape[1]
    for threads in (1, 2):
        torch.set_num_threads(threads)
        c = smg.node_confidences(x, (idx, w))
        xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()

        def carap():
            xs.grad = qs.grad = None
            smg.carap(xs, qs, (idx, w), c).backward()

        def lrm():
            xs.grad = None
            smg.lrm(xs, (idx, w), c).backward()

        for op, fn in (("carap", carap), ("lrm", lrm)):
            fn()  # warm-up
            smg._library_seconds(op, x, q, (idx, w), c, repeat=1)
            t_bind, t_lib = float("inf"), float("inf")
            for _ in range(repeat):  # interleaved, so that load drift hits both alike
                t_bind = min(t_bind, best_of(fn, 1))
                t_lib = min(t_lib, smg._library_seconds(op, x, q, (idx, w), c, repeat=1))
            what = "C-ARAP + grad x, q" if op == "carap" else "LRM + grad x"
            rows.append((f"{what}, N={N} T={T} K={K} float32, {threads} thread(s)", t_bind, t_lib))
    return rows


def print_overhead(rows, repeat):
    print(f"Binding overhead: smg_torch forward + backward against the bare C++ call (std::chrono in C++), "
          f"best of {repeat} interleaved, torch {torch.__version__}, {os.cpu_count()} CPUs\n")
    print("| operation | smg_torch fwd+bwd | bare C++ call | overhead |")
    print("|---|---:|---:|---:|")
    for name, a, b in rows:
        print(f"| {name} | {a * 1e3:.2f} ms | {b * 1e3:.2f} ms | {100 * (a / b - 1):+.1f} % |")


def rel(a, b):
    return float((a.double() - b.double()).norm() / b.double().norm())


def skin_scene(N, T, K, P, dtype=torch.float32):
    x, q, idx, w = energy_scene(N, T, K, torch.float64)
    g = torch.Generator().manual_seed(2)
    anchor = torch.randint(0, N, (P,), generator=g)
    t_ref = torch.zeros(P, dtype=torch.long)
    pts = x[0, anchor] + 0.1 * torch.randn(P, 3, generator=g, dtype=torch.float64)
    pq = torch.randn(P, 4, generator=g, dtype=torch.float64)
    sigma = torch.full((N,), 0.15, dtype=torch.float64)
    t_query = torch.tensor([T // 2])
    c = lambda t: t.to(dtype)  # noqa: E731
    return c(x), c(q), idx, c(w), c(pts), c(pq), anchor, t_ref, t_query, c(sigma)


def dqb_run(f, s):
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = s
    leaves = [t.clone().requires_grad_() for t in (x, q, pts, pq)]
    if f is smg:
        px, pqo = smg.dqb(leaves[0], leaves[1], (idx, w), leaves[2], leaves[3], anchor, t_ref, t_query, sigma)
    else:
        px, pqo = ref.dqb(leaves[0], leaves[1], idx, leaves[2], leaves[3], anchor, t_ref, t_query, sigma)
    (px.sum() + pqo.sum()).backward()
    return px.detach(), [t.grad for t in leaves]


def render_scene(G, W, H, dtype):
    import numpy as np
    import gsplat_reference as gref
    arrays, bg = gref.random_scene(np.random.default_rng(3), G, W, H, 3, -1)
    t = {k: torch.tensor(v, dtype=dtype) for k, v in arrays.items()}
    return t, torch.tensor(bg, dtype=dtype)


NAMES = ("means", "quats", "scales", "opacities", "colors")


def render_run(which, t, bg, W, H):
    p = {k: (v.clone().requires_grad_() if k in NAMES else v) for k, v in t.items()}
    if which == "smg":
        img, acc, depth = smg.render(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"],
                                     p["viewmat"], p["K"], W, H, background=bg)
    else:
        import gsplat_reference as gref
        img, acc, depth = gref.render(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"],
                                      p["viewmat"], p["K"], W, H, bg, -1)[:3]
    (img.sum() + acc.sum() + 0.1 * depth.sum()).backward()
    return img.detach(), [p[k].grad for k in NAMES]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    ap.add_argument("--overhead-only", action="store_true",
                    help="only the binding-overhead rows (smg_torch against the bare C++ call)")
    args = ap.parse_args()
    N, T, K, P, G, W, H = (5000, 100, 16, 32768, 100000, 320, 240)
    gs, ws, hs = 2000, 160, 120
    if args.quick:
        N, T, P, G, gs = 500, 20, 2048, 5000, 300
    old_threads = torch.get_num_threads()
    rows = []  # (name, smg seconds, torch seconds or None, note)

    x, q, idx, w = energy_scene(N, T, K)
    if args.overhead_only:
        print_overhead(overhead_rows(x, q, idx, w, max(args.repeat, 5)), max(args.repeat, 5))
        torch.set_num_threads(old_threads)
        return 0
    for threads in (1, 2):
        torch.set_num_threads(threads)
        energies_smg(x, q, idx, w)  # warm-up
        t_smg = best_of(lambda: energies_smg(x, q, idx, w), args.repeat)
        t_ref = best_of(lambda: energies_torch(x, q, idx, w), args.repeat)
        rows.append((f"energies fwd+bwd (conf + C-ARAP + LRM + ARAP), N={N} T={T} K={K} float32, {threads} thread(s)",
                     t_smg, t_ref))
    overhead = overhead_rows(x, q, idx, w, max(args.repeat, 5))
    e1, gx1, gq1 = energies_smg(x, q, idx, w)
    e2, gx2, gq2 = energies_torch(x, q, idx, w)
    agree = f"float32 agreement: energy {abs(e1 - e2) / abs(e2):.1e}, grad x {rel(gx1, gx2):.1e}, grad q {rel(gq1, gq2):.1e}"

    torch.set_num_threads(2)
    s = skin_scene(N, T, K, P)
    dqb_run(smg, s)
    t_smg = best_of(lambda: dqb_run(smg, s), args.repeat)
    t_ref = best_of(lambda: dqb_run(ref, s), args.repeat)
    rows.append((f"DQB fwd+bwd, P={P} points x {K + 1} drivers, 1 query frame, float32, 2 threads", t_smg, t_ref))

    t, bg = render_scene(G, W, H, torch.float32)
    render_run("smg", t, bg, W, H)
    t_smg = best_of(lambda: render_run("smg", t, bg, W, H), args.repeat)
    rows.append((f"render fwd+bwd, {G} Gaussians, {W}x{H}, float32, 2 threads", t_smg, None))
    # the dense reference computes in float64 (gsplat_reference.py sets the default dtype)
    t, bg = render_scene(gs, ws, hs, torch.float64)
    t_smg = best_of(lambda: render_run("smg", t, bg, ws, hs), args.repeat)
    t_ref = best_of(lambda: render_run("ref", t, bg, ws, hs), args.repeat)
    rows.append((f"render fwd+bwd, {gs} Gaussians, {ws}x{hs}, float64, 2 threads", t_smg, t_ref))
    torch.set_num_threads(old_threads)

    print(f"smg_torch vs pure-PyTorch autograd, best of {args.repeat}, torch {torch.__version__}, "
          f"{os.cpu_count()} CPUs\n")
    print("| operation | smg_torch | PyTorch autograd | speed-up |")
    print("|---|---:|---:|---:|")
    for name, a, b in rows:
        print(f"| {name} | {a * 1e3:.1f} ms | " + (f"{b * 1e3:.1f} ms | {b / a:.1f}x |" if b else
              "n/a (dense reference: H*W*G = %.1e pairs) | |" % (W * H * G)))
    print(f"\n{agree}\n")
    print_overhead(overhead, max(args.repeat, 5))
    if args.json:
        bench = []
        for name, a, b in rows:
            entry = {"name": name, "run_type": "iteration", "iterations": args.repeat,
                     "real_time": a * 1e3, "cpu_time": a * 1e3, "time_unit": "ms"}
            entry["pytorch_ms"] = b * 1e3 if b else float("nan")
            entry["speedup"] = b / a if b else float("nan")
            bench.append(entry)
        for name, a, b in overhead:
            bench.append({"name": "overhead: " + name, "run_type": "iteration", "iterations": max(args.repeat, 5),
                          "real_time": a * 1e3, "cpu_time": a * 1e3, "time_unit": "ms",
                          "library_ms": b * 1e3, "overhead_percent": 100 * (a / b - 1)})
        ctx = {"date": datetime.datetime.now().isoformat(timespec="seconds"),
               "num_cpus": os.cpu_count(), "mhz_per_cpu": "?",
               "library_build_type": "release (smg_torch extension, -O3)"}
        with open(args.json, "w") as f:
            json.dump({"context": ctx, "benchmarks": bench}, f, indent=1, allow_nan=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
