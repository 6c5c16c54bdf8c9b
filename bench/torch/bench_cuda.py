#!/usr/bin/env python3
"""smg_torch's CUDA operators against pure-PyTorch autograd on the same GPU: forward + backward,
CUDA-event timing, best and median of --repeat runs after a warm-up.

usage: PYTHONPATH=<smg_torch built with CUDA> python3 bench/torch/bench_cuda.py [--repeat 20]
           [--json out.json] [--quick]
       ... bench_cuda.py --scaling [--repeat 20] [--json out.json] [--quick]

Energies: the scene of bench_torch.py (N = 5000 nodes, T = 100 frames, K = 16, gaps 1,2,4,
float32), loss = C-ARAP + LRM + ARAP with node confidences computed first, backward to the
positions and raw quaternions, through the four operators and through the fused step
(smg_torch.regularizers); each operator is also timed alone. The PyTorch baseline is
tests/torch/torch_reference.py (vectorised autograd implementations of docs/math/energy.md)
on the same device, run eagerly and through torch.compile (timed after its first call, which
compiles and is reported on its own; without torch.compile, torch 1.x, the row says so).
DQB: 32768 points x 17 drivers when smg_torch has cuda_dqb.
Scaling (--scaling): the energies at bench_torch.SCALING_SIZES (5k x 100 ... 200k x 100, 50k x
400) for smg, eager and compile: best time, ns per (edge, frame, gap) term and peak memory
(torch.cuda.max_memory_allocated after a reset, minus what was allocated before: the inputs);
a peer whose extrapolated peak exceeds 90 % of the device's memory is skipped, one that runs out
of memory is reported so.
Prints a markdown table with the device name; --json writes the rows. Without a CUDA device,
or with an smg_torch built without its CUDA operators (the CMake route), it prints one
"bench_cuda: error: ..." line on stderr and exits 1.
"""
import argparse
import functools
import json
import os
import statistics
import sys

import torch

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "tests", "torch"))
sys.path.insert(0, HERE)

try:
    import smg_torch as smg  # noqa: E402
except ImportError as e:
    sys.exit("bench_cuda: error: cannot import smg_torch (%s): put the package on PYTHONPATH (docs/torch.md)" % e)
import torch_reference as ref  # noqa: E402
from bench_torch import (SCALING_QUICK, SCALING_SIZES, compiled_peer, energy_fused, energy_ref,  # noqa: E402
                         energy_scene, energy_smg, fwd_bwd, print_scaling, scaling_json, scaling_scene,
                         scaling_table, skin_scene)


def timed(fn, repeat):
    """(best, median) seconds of fn() by CUDA events, after two warm-up calls."""
    fn()
    fn()
    times = []
    for _ in range(repeat):
        a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        a.record()
        fn()
        b.record()
        torch.cuda.synchronize()
        times.append(a.elapsed_time(b) * 1e-3)
    return min(times), statistics.median(times)


def best(fn, repeat):
    return timed(fn, repeat)[0]


def cuda_scaling(args, dev, name, has_lrm):
    """--scaling on the GPU: smg, eager and compile at SCALING_SIZES (SCALING_QUICK with --quick);
    the graph is built on the CPU (bench_torch.scaling_scene), then moved."""
    def e_smg(xs, qs, idx, w):
        return energy_smg(xs, qs, idx, w, lrm=has_lrm)

    def e_ref(xs, qs, idx, w):  # a plain function for torch.compile to trace
        return energy_ref(xs, qs, idx, w, lrm=has_lrm)

    def measure(energy, x, q, idx, w):
        torch.cuda.synchronize()
        base = torch.cuda.memory_allocated()
        torch.cuda.reset_peak_memory_stats()
        t = best(lambda: fwd_bwd(energy, x, q, idx, w), args.repeat)
        return {"seconds": t, "peak_bytes": torch.cuda.max_memory_allocated() - base}

    def peer_compile(x, q, idx, w):
        torch.cuda.synchronize()
        base = torch.cuda.memory_allocated()
        torch.cuda.reset_peak_memory_stats()
        r = compiled_peer(e_ref, lambda fn: fwd_bwd(fn, x, q, idx, w), args.repeat, best,
                          torch.cuda.synchronize)
        if "seconds" in r:
            r["peak_bytes"] = torch.cuda.max_memory_allocated() - base
        return r

    def on_device(f):
        def run(x, q, idx, w):
            try:
                return f(x.to(dev), q.to(dev), idx.to(dev), w.to(dev))
            finally:
                torch.cuda.empty_cache()
        return run

    peers = [("smg", on_device(functools.partial(measure, e_smg))),
             ("eager", on_device(functools.partial(measure, e_ref))),
             ("compile", on_device(peer_compile))]
    limit = 0.9 * torch.cuda.get_device_properties(dev).total_memory
    rows = scaling_table(SCALING_QUICK if args.quick else SCALING_SIZES, 16, peers, 600.0, limit,
                         scaling_scene)
    terms = "conf + C-ARAP + ARAP" + (" + LRM" if has_lrm else "")
    print_scaling(rows, f"Scaling ({terms}, fwd+bwd, float32) on {name}, CUDA events, best of {args.repeat} "
                        f"after 2 warm-ups, torch {torch.__version__}",
                  "torch.cuda.max_memory_allocated() over the calls after reset_peak_memory_stats(), "
                  "minus memory_allocated() before (the inputs)")
    if args.json:
        out = {"context": {"device": name, "torch": torch.__version__, "repeat": args.repeat,
                           "terms": terms, "peak_memory": "max_memory_allocated - inputs"},
               "benchmarks": [dict(b, device=name) for b in scaling_json(rows, "GPU")]}
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


def rel(a, b):
    return float((a.double() - b.double()).norm() / b.double().norm().clamp_min(1e-300))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--profile", action="store_true",
                    help="print the CUDA kernel times of one smg_torch energies call (torch.profiler)")
    ap.add_argument("--scaling", action="store_true",
                    help="only the scaling table (bench_torch.SCALING_SIZES; tiny sizes with --quick)")
    args = ap.parse_args()
    # Nothing to measure is a failure, not a skip: a run that printed "skipped" and exited 0 left
    # the GPU tables of docs/performance.md unmeasured without anyone noticing (issue 36).
    if not smg.has_cuda:
        print("bench_cuda: error: smg_torch (%s) was built without its CUDA operators (has_cuda is False); "
              "they are built by the pip route only, with nvcc and a CUDA build of torch (docs/torch.md, "
              "\"Building it\"); the CMake route builds the CPU operators only" % os.path.dirname(smg.__file__),
              file=sys.stderr)
        return 1
    if not torch.cuda.is_available():
        print("bench_cuda: error: no CUDA device (torch.cuda.is_available() is False)", file=sys.stderr)
        return 1
    dev = torch.device("cuda")
    name = torch.cuda.get_device_name(dev)
    # A CUDA build of smg_torch registers every operator's CUDA launch (smg_torch_cuda.cu's
    # register_cuda); the per-operator "cuda_*" attributes this once read are gone, and reading
    # them left LRM, DQB and the per-operator rows out of every run.
    has = {op: bool(smg.has_cuda) for op in ("carap", "arap", "lrm", "dqb_forward", "regularizers")}
    if args.scaling:
        cuda_scaling(args, dev, name, has["lrm"])
        return 0
    N, T, K, P = (500, 20, 16, 2048) if args.quick else (5000, 100, 16, 32768)
    x, q, idx, w = (t.to(dev) for t in energy_scene(N, T, K))
    ref_only = ["dqb"] if not has["dqb_forward"] else []
    g = (idx, w)

    def loss(f, xs, qs):
        c = f.node_confidences(xs, idx, w) if f is ref else f.node_confidences(xs, g)
        e = (ref.carap(xs, qs, idx, w, c) if f is ref else smg.carap(xs, qs, g, c))
        e = e + (ref.arap(xs, qs, idx, w) if f is ref else smg.arap(xs, qs, g))
        if has["lrm"]:
            e = e + (ref.lrm(xs, idx, w, c) if f is ref else smg.lrm(xs, g, c))
        return e

    def run(f):
        xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
        e = loss(f, xs, qs)
        e.backward()
        return e.detach(), xs.grad, qs.grad

    rows = []
    terms = "conf + C-ARAP + ARAP" + (" + LRM" if has["lrm"] else "")
    t_smg = timed(lambda: run(smg), args.repeat)
    t_ref = timed(lambda: run(ref), args.repeat)
    rows.append((f"energies fwd+bwd ({terms}), N={N} T={T} K={K} float32", t_smg, t_ref))
    if has["regularizers"] and has["lrm"]:
        # The same sum through the fused step (smg::cuda::regularizers), against the same eager peer.
        t_fused = timed(lambda: fwd_bwd(energy_fused, x, q, idx, w), args.repeat)
        rows.append((f"the same, fused (smg_torch.regularizers), N={N} T={T} K={K} float32",
                     t_fused, t_ref))
    # torch.compile of the same PyTorch code (energy_ref is loss(ref, ...) as a function of leaves)
    def e_ref(xs, qs, idx, w):  # a plain function for torch.compile to trace
        return energy_ref(xs, qs, idx, w, lrm=has["lrm"])
    t_cmp = compiled_peer(e_ref, lambda fn: fwd_bwd(fn, x, q, idx, w), args.repeat, timed,
                          torch.cuda.synchronize)
    e1, gx1, gq1 = run(smg)
    e2, gx2, gq2 = run(ref)
    agree = (f"float32, smg CUDA vs PyTorch autograd CUDA: energy {abs(float(e1 - e2)) / abs(float(e2)):.1e}, "
             f"grad x {rel(gx1, gx2):.1e}, grad q {rel(gq1, gq2):.1e}")
    if has["regularizers"] and has["lrm"]:
        e3, gx3, gq3 = fwd_bwd(energy_fused, x, q, idx, w)
        agree += (f"; fused step vs PyTorch autograd: energy {abs(float(e3 - e2)) / abs(float(e2)):.1e}, "
                  f"grad x {rel(gx3, gx2):.1e}, grad q {rel(gq3, gq2):.1e}")
    # Against float64 on the CPU (the library's reference precision) on the same inputs.
    xd, qd, wd = x.double().cpu(), q.double().cpu(), w.double().cpu()
    xs, qs = xd.clone().requires_grad_(), qd.clone().requires_grad_()
    cd = smg.node_confidences(xs, (idx.cpu(), wd))
    ed = smg.carap(xs, qs, (idx.cpu(), wd), cd) + smg.arap(xs, qs, (idx.cpu(), wd))
    if has["lrm"]:
        ed = ed + smg.lrm(xs, (idx.cpu(), wd), cd)
    ed.backward()
    ed = float(ed.detach())
    agree64 = (f"float32 CUDA vs float64 CPU (same inputs): energy {abs(float(e1) - ed) / abs(ed):.1e}, "
               f"grad x {rel(gx1.cpu(), xs.grad):.1e}, grad q {rel(gq1.cpu(), qs.grad):.1e}")

    c = smg.node_confidences(x, g)
    for op in ("node_confidences", "carap", "arap", "lrm"):
        if op != "node_confidences" and not has[op]:
            continue
        def one(f, op=op):
            xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
            if op == "node_confidences":
                return f.node_confidences(xs, idx, w) if f is ref else f.node_confidences(xs, g)
            if op == "carap":
                e = ref.carap(xs, qs, idx, w, c) if f is ref else smg.carap(xs, qs, g, c)
            elif op == "arap":
                e = ref.arap(xs, qs, idx, w) if f is ref else smg.arap(xs, qs, g)
            else:
                e = ref.lrm(xs, idx, w, c) if f is ref else smg.lrm(xs, g, c)
            e.backward()
        rows.append((f"{op} {'fwd' if op == 'node_confidences' else 'fwd+bwd'}, N={N} T={T} K={K} float32",
                     timed(lambda: one(smg), args.repeat), timed(lambda: one(ref), args.repeat)))

    if has["dqb_forward"]:
        s = [t.to(dev) for t in skin_scene(N, T, K, P)]
        xs_, qs_, idx_, w_, pts, pq, anchor, t_ref, t_query, sigma = s

        def dqb(f):
            leaves = [t.clone().requires_grad_() for t in (xs_, qs_, pts, pq)]
            if f is smg:
                px, pqo = smg.dqb(leaves[0], leaves[1], (idx_, w_), leaves[2], leaves[3], anchor, t_ref,
                                  t_query, sigma)
            else:
                px, pqo = ref.dqb(leaves[0], leaves[1], idx_, leaves[2], leaves[3], anchor, t_ref,
                                  t_query, sigma)
            (px.sum() + pqo.sum()).backward()
        rows.append((f"DQB fwd+bwd, P={P} points x {K + 1} drivers, 1 query frame, float32",
                     timed(lambda: dqb(smg), args.repeat), timed(lambda: dqb(ref), args.repeat)))

    if args.profile:
        from torch.profiler import ProfilerActivity, profile
        run(smg)
        torch.cuda.synchronize()
        with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
            run(smg)
            torch.cuda.synchronize()
        print(prof.key_averages().table(sort_by="cuda_time_total", row_limit=25))

    if ref_only and not args.quick:
        # PyTorch autograd alone (smg's DQB kernels are timed by bench/cuda/bench_cuda, without
        # the drivers and weights, which a trainer keeps): the reference row for comparison.
        s = [t.to(dev) for t in skin_scene(N, T, K, P)]
        xs_, qs_, idx_, w_, pts, pq, anchor, t_ref, t_query, sigma = s

        def dqb_ref():
            leaves = [t.clone().requires_grad_() for t in (xs_, qs_, pts, pq)]
            px, pqo = ref.dqb(leaves[0], leaves[1], idx_, leaves[2], leaves[3], anchor, t_ref,
                              t_query, sigma)
            (px.sum() + pqo.sum()).backward()
        t = timed(dqb_ref, args.repeat)
        print(f"PyTorch autograd DQB fwd+bwd (drivers, weights and blend), P={P} points x {K + 1} "
              f"drivers, 1 query frame, float32: {t[0] * 1e3:.3f} ms ({t[1] * 1e3:.3f})")

    missing = [op for op, ok in has.items() if not ok]
    print(f"smg_torch CUDA vs pure-PyTorch autograd on {name}, CUDA events, best and median of "
          f"{args.repeat} after 2 warm-ups, torch {torch.__version__}\n")
    print("| operation | smg_torch best (median) | PyTorch autograd best (median) | speed-up (best) |")
    print("|---|---:|---:|---:|")
    for rname, a, b in rows:
        print(f"| {rname} | {a[0] * 1e3:.3f} ms ({a[1] * 1e3:.3f}) | {b[0] * 1e3:.3f} ms ({b[1] * 1e3:.3f}) | "
              f"{b[0] / a[0]:.1f}x |")
    if "seconds" in t_cmp:
        b, m = t_cmp["seconds"]
        print(f"\ntorch.compile of the same PyTorch code, energies fwd+bwd ({terms}): {b * 1e3:.3f} ms "
              f"({m * 1e3:.3f}) after compiling in {t_cmp['compile_s']:.1f} s (first call); "
              f"{b / rows[0][1][0]:.1f}x smg_torch")
    else:
        print(f"\n{t_cmp['note']}")
    print(f"\n{agree}\n{agree64}")
    if missing:
        print(f"not measured (no CUDA operator in this build): {', '.join(missing)}")
    if args.json:
        out = {"context": {"device": name, "torch": torch.__version__, "repeat": args.repeat},
               "benchmarks": [{"name": r, "real_time": a[0] * 1e3, "median_ms": a[1] * 1e3,
                               "pytorch_ms": b[0] * 1e3, "pytorch_median_ms": b[1] * 1e3,
                               "speedup": b[0] / a[0], "time_unit": "ms", "device": name}
                              for r, a, b in rows],
               "agreement": [agree, agree64]}
        e = out["benchmarks"][0]
        if "seconds" in t_cmp:
            e.update(compile_ms=t_cmp["seconds"][0] * 1e3, compile_median_ms=t_cmp["seconds"][1] * 1e3,
                     compile_time_s=t_cmp["compile_s"], compile_speedup=t_cmp["seconds"][0] / rows[0][1][0])
        else:
            e["compile_note"] = t_cmp["note"]  # no number where torch has no torch.compile
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
