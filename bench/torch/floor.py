#!/usr/bin/env python3
"""The floor beside every figure (issue 59) for the torch benchmarks: max(flops / peak, bytes /
bandwidth) of a case on this machine, and the time's ratio to it.

usage: /usr/bin/python3 bench/torch/floor.py [--floor-json FILE]
       /usr/bin/python3 bench/torch/floor.py --torch [--threads N]
       /usr/bin/python3 bench/torch/floor.py --check build/release/bench/bench_floor

The counts: bench/floor.hpp holds the per-unit flop counts (derived in bench/notes/roofline.md);
this module reads them from that file (its `constexpr double kName = number;` lines), so they
live in one place, and mirrors the few formulas that turn a shape into (flops, bytes). --check
runs `bench_floor --counts` (the C++ functions at fixed shapes) and compares every case with
this module's result at the same shapes; it exits 1 on a difference.

The machine comes from the C++ probe, never from torch: --floor-json FILE (or SMG_FLOOR_JSON)
reads bench_floor --json=FILE's output; without it the newest build/*/bench/bench_floor is run
(~4 s: multiply-add chains in registers on all cores, SSE2 and AVX2+FMA, and a STREAM triad);
with neither, the floor columns say n/a. Why not torch: a GEMM (torch.mm) measures the BLAS
torch was built with, not the cores; Debian's torch 1.13 on this machine (BLAS_INFO=generic)
reaches 3.9 GFLOP/s in a 2048³ torch.mm against the cores' ~100 GFLOP/s per core of AVX2 FMA,
so a floor from it would be 30 times too high. `--torch` prints what torch reaches (torch.mm
2048³ and a triad torch.add(b, c, alpha=s, out=a) over 3 × 128 MB float64), for comparison. One
probe behind every table also makes the C++ and the torch rows' floors the same.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
HEADER = os.path.join(HERE, "..", "floor.hpp")


def _constants():
    with open(HEADER) as f:
        text = f.read()
    k = {m.group(1): float(m.group(2))
         for m in re.finditer(r"constexpr double k(\w+) = ([0-9.eE+-]+);", text)}
    if not k:
        raise RuntimeError(f"no counts found in {HEADER}")
    return k


K = _constants()


# ---- the counts (bench/floor.hpp's functions, the same formulas) ---------------------------------
class Shape:
    """A regulariser problem: T frames, N nodes, E valid edges, pair_frames = sum over gaps of
    (T - gap); scalar bytes, index bytes (smg_torch: int64), vis bytes per (node, frame) (0:
    absent), rot_grad = the rotation gradient's width (smg_torch: quaternions, 4)."""

    def __init__(self, T, N, E, gaps=(1, 2, 4), scalar=4, index=8, vis=0, rot_grad=4, pair_frames=None):
        self.T, self.N, self.E = float(T), float(N), float(E)
        self.pair_frames = float(pair_frames if pair_frames is not None else sum(max(0, T - d) for d in gaps))
        self.scalar, self.index, self.vis, self.rot_grad = float(scalar), float(index), float(vis), float(rot_grad)

    def ef(self):
        return self.E * self.T

    def efg(self):
        return self.E * self.pair_frames

    def nf(self):
        return self.N * self.T

    def frame_array(self, width):
        return self.T * self.N * width * self.scalar

    def graph(self):
        return self.E * (self.index + self.scalar)


def confidences(s):
    return (K["ConfEF"] * s.ef() + K["ConfNF"] * s.nf(),
            s.frame_array(3) + s.T * s.N * s.vis + s.graph() + s.frame_array(1))


def rigidity(s, with_conf, grad):
    p = ("Carap" if with_conf else "Arap") + ("Grad" if grad else "")
    return (K[p + "EF"] * s.ef() + K[p + "EFG"] * s.efg() + K[p + "NF"] * s.nf(),
            s.frame_array(3) + s.frame_array(4) + (s.frame_array(1) if with_conf else 0) + s.graph()
            + (s.frame_array(3) + s.frame_array(s.rot_grad) if grad else 0))


def lrm(s, mode):
    ef = K["LrmEF"] if mode == 0 else K["LrmGradEF"] if mode == 1 else K["LrmDetachedGradEF"]
    return (ef * s.ef() + K["LrmNF"] * s.nf(),
            s.frame_array(3) + s.frame_array(1) + s.graph() + (s.frame_array(3) if mode > 0 else 0))


def step(s, grad):
    p = "StepGrad" if grad else "Step"
    return (K[p + "EF"] * s.ef() + K[p + "EFG"] * s.efg() + K[p + "NF"] * s.nf(),
            s.frame_array(3) + s.frame_array(4) + s.T * s.N * s.vis + s.graph() + s.frame_array(1)
            + (s.frame_array(3) + s.frame_array(s.rot_grad) if grad else 0))


def carap_plus_lrm(s):
    c, l = rigidity(s, True, True), lrm(s, 1)
    return (c[0] + l[0], c[1])


def accel(s):
    return (K["AccelTerm"] * max(0.0, s.T - 2) * s.N, 2 * s.frame_array(3))


def som_accel(terms, elements, shared, scalar=4):
    return ((K["SomTerm"] + (K["SomShared"] if shared else 0)) * terms, 2 * elements * scalar)


def mosca_arap(T, M, E, pair_frames, graph_bytes, scalar=4):
    return (K["MoscaArapEF"] * E * T + K["MoscaArapEFS"] * E * pair_frames + K["MoscaArapNF"] * M * T,
            2 * T * M * 7 * scalar + graph_bytes)


def mosca_vel_acc(T, M, scalar=4):
    return (K["MoscaVelNF"] * T * M + K["MoscaVelPair"] * max(0.0, T - 1) * M
            + K["MoscaVelTriple"] * max(0.0, T - 2) * M, 2 * T * M * 7 * scalar)


def d3dgs(N, Kn, scalar=4):
    return (K["D3dgsEdge"] * N * Kn + K["D3dgsNode"] * N, 3 * N * 7 * scalar + N * Kn * (8 + 2 * scalar))


def check_cases():
    """The shapes of bench_floor --counts (bench/floor_probe.cpp), evaluated here."""
    s = Shape(100, 5000, 80000, pair_frames=3 * 100 - 7, scalar=4, index=8, vis=1, rot_grad=4)
    return {"confidences": confidences(s), "carap": rigidity(s, True, False), "carap_grad": rigidity(s, True, True),
            "arap": rigidity(s, False, False), "arap_grad": rigidity(s, False, True), "lrm": lrm(s, 0),
            "lrm_grad": lrm(s, 1), "lrm_detached_grad": lrm(s, 2), "step": step(s, False), "step_grad": step(s, True),
            "carap_plus_lrm": carap_plus_lrm(s), "accel": accel(s),
            "som_accel": som_accel(40000.0 * 8, 40000.0 * 3 * 8 * 3, False),
            "som_accel_shared": som_accel(40000.0 * 28, 40000.0 * 30 * 3, True),
            "mosca_arap": mosca_arap(25, 10000, 150000, 25 * 3 - 10, 10000.0 * 16 * 9),
            "mosca_vel_acc": mosca_vel_acc(25, 10000), "d3dgs": d3dgs(100000, 20)}


def check(binary):
    out = subprocess.run([binary, "--counts"], check=True, stdout=subprocess.PIPE, text=True).stdout
    cpp = {r["case"]: (r["flops"], r["bytes"]) for r in map(json.loads, out.splitlines())}
    py = check_cases()
    bad = [c for c in set(cpp) | set(py)
           if c not in cpp or c not in py or any(abs(a - b) > 1e-9 * max(1.0, abs(b)) for a, b in zip(cpp[c], py[c]))]
    for c in sorted(bad):
        print(f"floor.py --check: {c}: C++ {cpp.get(c)} != Python {py.get(c)}")
    if not bad:
        print(f"floor.py --check: {len(py)} cases agree with {binary} --counts")
    return 1 if bad else 0


# ---- the machine --------------------------------------------------------------------------------
class Machine:
    def __init__(self, fp32_gflops, fp64_gflops, bandwidth_gbs, how):
        self.fp32_gflops, self.fp64_gflops, self.bandwidth_gbs, self.how = fp32_gflops, fp64_gflops, bandwidth_gbs, how

    def floor_seconds(self, work, scalar=4):
        """max(flops / peak, bytes / bandwidth) of work = (flops, bytes), FP32 peak unless scalar = 8;
        0 where the machine is unknown."""
        if self.bandwidth_gbs <= 0:
            return 0.0
        flops, nbytes = work
        peak = (self.fp64_gflops if scalar == 8 else self.fp32_gflops) * 1e9
        return max(flops / peak if peak > 0 else 0.0, nbytes / (self.bandwidth_gbs * 1e9) if self.bandwidth_gbs > 0 else 0.0)

    def describe(self):
        if self.bandwidth_gbs <= 0:
            return f"floor: n/a ({self.how})"
        return (f"floor = max(flops / peak, bytes / bandwidth): FP32 {self.fp32_gflops:.1f} GFLOP/s, "
                f"{self.bandwidth_gbs:.1f} GB/s ({self.how})")


def load(path):
    with open(path) as f:
        j = json.load(f)
    return Machine(j["fp32_gflops"], j.get("fp64_gflops", 0.0), j["bandwidth_gbs"],
                   f"bench_floor, {j.get('best_isa', '?')}, {j.get('threads', '?')} threads: {path}")


def measure_torch(threads=None):
    """What torch reaches on `threads` (default: all CPUs) threads (not used for the floor: see the
    module's text); the caller's setting restored."""
    import torch
    old = torch.get_num_threads()
    threads = threads or os.cpu_count() or 1
    torch.set_num_threads(threads)
    try:
        gflops = {}
        n = 2048
        for dt in (torch.float32, torch.float64):
            a, b = torch.rand(n, n, dtype=dt), torch.rand(n, n, dtype=dt)
            torch.mm(a, b)
            best = float("inf")
            for _ in range(5):
                t0 = time.perf_counter()
                torch.mm(a, b)
                best = min(best, time.perf_counter() - t0)
            gflops[dt] = 2.0 * n ** 3 / best / 1e9
        m = 16 << 20
        a, b, c = torch.zeros(m, dtype=torch.float64), torch.ones(m, dtype=torch.float64), torch.ones(m, dtype=torch.float64)
        torch.add(b, c, alpha=0.5, out=a)
        best = float("inf")
        for _ in range(5):
            t0 = time.perf_counter()
            torch.add(b, c, alpha=0.5, out=a)
            best = min(best, time.perf_counter() - t0)
        bw = 3 * 8 * m / best / 1e9
    finally:
        torch.set_num_threads(old)
    return Machine(gflops[torch.float32], gflops[torch.float64], bw,
                   f"measured with torch on {threads} threads: torch.mm 2048^3, triad 3 x 128 MB")


def probe_binary():
    """The newest build/*/bench/bench_floor, or None."""
    import glob
    found = glob.glob(os.path.join(HERE, "..", "..", "build", "*", "bench", "bench_floor"))
    found = [f for f in found if os.access(f, os.X_OK)]
    return os.path.normpath(max(found, key=os.path.getmtime)) if found else None


def machine(floor_json=None):
    """--floor-json FILE if given (or SMG_FLOOR_JSON), else bench_floor run now, else unknown."""
    path = floor_json or os.environ.get("SMG_FLOOR_JSON")
    if path:
        return load(path)
    binary = probe_binary()
    if binary is None:
        return Machine(0.0, 0.0, 0.0, "no bench_floor built and no --floor-json: build the target bench_floor")
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "floor.json")
        subprocess.run([binary, "--json=" + out], check=True, stdout=subprocess.DEVNULL)
        m = load(out)
    m.how = m.how.replace(out, f"measured now by {binary}")
    return m


def cells(m, work, seconds, scalar=4):
    """(floor text, ratio text) for a table: the floor in ms and time / floor."""
    if work is None or m.bandwidth_gbs <= 0:
        return "n/a", ""
    f = m.floor_seconds(work, scalar)
    ratio = f"{seconds / f:.1f}x" if seconds is not None and f > 0 and seconds == seconds else ""
    return f"{f * 1e3:.3g} ms", ratio


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--torch", action="store_true", help="print what torch reaches (torch.mm, a triad): not the floor's peak")
    ap.add_argument("--threads", type=int, default=None, help="--torch: threads (default: all CPUs)")
    ap.add_argument("--floor-json", default=None, help="bench_floor --json=FILE's output instead of measuring")
    ap.add_argument("--check", default=None, metavar="BENCH_FLOOR",
                    help="compare this module's counts with BENCH_FLOOR --counts (exit 1 on a difference)")
    a = ap.parse_args()
    if a.check:
        return check(a.check)
    m = measure_torch(a.threads) if a.torch else machine(a.floor_json)
    print(f"FP32 {m.fp32_gflops:.1f} GFLOP/s, FP64 {m.fp64_gflops:.1f} GFLOP/s, {m.bandwidth_gbs:.1f} GB/s ({m.how})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
