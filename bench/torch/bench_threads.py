#!/usr/bin/env python3
"""smg's loops inside a torch process at 1 and 2 torch threads (issue 24): best of --repeat runs.

usage: PYTHONPATH=<build>/python /usr/bin/python3 bench/torch/bench_threads.py [--repeat 7]
           [--cli <build>/examples/smg_cli]

Case: bench_torch.py's energy scene, N = 5000, T = 100, K = 16, gaps 1,2,4, float32. For each
torch.set_num_threads(t), t = 1, 2, prints
  - the bare library call timed in C++ (smg_torch._library_seconds, "carap" and "lrm"), with
    the process's CPU seconds over wall seconds of the whole call (all repeats);
  - smg_torch.carap and smg_torch.arap forward + backward: wall seconds and the process's CPU
    seconds (time.process_time, all threads) of the best run by wall time; CPU / wall near t
    means the loop used t cores, near 1 that it ran on one (or that other processes held the
    cores); and each thread's share of the process's CPU ticks over all runs (/proc/self/task),
    which shows how the work was split whatever the load: "100" = one thread did everything,
    "50/50" = two threads split it;
  - with --cli, smg_cli energies on the same case (npy files, --float --threads t): its own
    seconds_carap / seconds_arap / seconds_lrm, best of --repeat processes.
OMP_WAIT_POLICY=PASSIVE as in bench_torch.py: spinning OpenMP threads make 2-thread timings on a
shared, loaded machine erratic.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import smg_torch as smg  # noqa: E402
from bench_torch import energy_scene  # noqa: E402


def thread_ticks():
    """{thread id: user + system CPU clock ticks} of this process's threads (Linux /proc)."""
    ticks = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            ticks[tid] = int(fields[11]) + int(fields[12])  # utime, stime (fields 14, 15)
        except OSError:
            pass
    return ticks


def shares(before, after):
    """Each thread's share of the CPU ticks between two thread_ticks(), in %, largest first,
    threads under 2 % left out: "50/50" when two threads split the work evenly."""
    d = [after[t] - before.get(t, 0) for t in after]
    total = sum(d) or 1
    return "/".join(f"{100 * v / total:.0f}" for v in sorted(d, reverse=True) if 100 * v / total >= 2)


def best_wall_cpu(fn, repeat):
    """(wall, cpu, shares): seconds of the run with the smallest wall time and the per-thread
    CPU shares over all runs."""
    best = (float("inf"), float("inf"))
    k0 = thread_ticks()
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        if wall < best[0]:
            best = (wall, cpu)
    return best + (shares(k0, thread_ticks()),)


def cli_seconds(cli, x, q, idx, w, threads, repeat):
    """Best of `repeat` smg_cli energies processes: {'carap': s, 'arap': s, 'lrm': s}."""
    with tempfile.TemporaryDirectory() as tmp:
        case, out = os.path.join(tmp, "case"), os.path.join(tmp, "out")
        os.makedirs(case)
        np.save(os.path.join(case, "positions.npy"), x.numpy())
        np.save(os.path.join(case, "quats.npy"), q.numpy())
        np.save(os.path.join(case, "graph_indices.npy"), idx.numpy())
        np.save(os.path.join(case, "graph_weights.npy"), w.numpy())
        best = {"carap": float("inf"), "arap": float("inf"), "lrm": float("inf")}
        for _ in range(repeat):
            r = subprocess.run([cli, "energies", case, out, "--float", "--threads", str(threads)],
                               check=True, capture_output=True, text=True)
            summary = json.loads(r.stdout.strip().splitlines()[-1])
            for k in best:
                best[k] = min(best[k], summary["seconds_" + k])
        return best


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--cli", help="path of smg_cli: also time smg_cli energies on the same case")
    args = ap.parse_args()
    x, q, idx, w = energy_scene(5000, 100, 16)
    print(f"N=5000 T=100 K=16 float32, best of {args.repeat}, torch {torch.__version__}, "
          f"{os.cpu_count()} CPUs, OMP_WAIT_POLICY={os.environ['OMP_WAIT_POLICY']}\n")
    print("| threads | what | wall | process CPU (/ wall) | CPU share per thread, % |")
    print("|---:|---|---:|---:|---|")
    for threads in (1, 2):
        torch.set_num_threads(threads)
        c = smg.node_confidences(x, (idx, w))
        for op in ("carap", "lrm"):
            smg._library_seconds(op, x, q, (idx, w), c, repeat=1)  # warm-up
            k0, c0, t0 = thread_ticks(), time.process_time(), time.perf_counter()
            s = smg._library_seconds(op, x, q, (idx, w), c, repeat=args.repeat)
            ratio = (time.process_time() - c0) / (time.perf_counter() - t0)  # over all repeats
            print(f"| {threads} | _library_seconds(\"{op}\") | {s * 1e3:.1f} ms | ({ratio:.2f}x) "
                  f"| {shares(k0, thread_ticks())} |")
        xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()

        def carap():
            xs.grad = qs.grad = None
            smg.carap(xs, qs, (idx, w), c).backward()

        def arap():
            xs.grad = qs.grad = None
            smg.arap(xs, qs, (idx, w)).backward()

        for name, fn in (("smg_torch.carap fwd+bwd", carap), ("smg_torch.arap fwd+bwd", arap)):
            fn()  # warm-up
            wall, cpu, share = best_wall_cpu(fn, args.repeat)
            print(f"| {threads} | {name} | {wall * 1e3:.1f} ms | {cpu * 1e3:.1f} ms ({cpu / wall:.2f}x) "
                  f"| {share} |")
        if args.cli:
            s = cli_seconds(args.cli, x, q, idx, w, threads, args.repeat)
            for k in ("carap", "arap", "lrm"):
                print(f"| {threads} | smg_cli energies seconds_{k} | {s[k] * 1e3:.1f} ms | | |")


if __name__ == "__main__":
    main()
