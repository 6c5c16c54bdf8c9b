#!/usr/bin/env python3
"""smg_torch against pure-PyTorch autograd (CPU): forward + backward, best of --repeat runs.

usage: PYTHONPATH=<build>/python /usr/bin/python3 bench/torch/bench_torch.py [--repeat 5]
           [--json bench/results/torch.json] [--quick] [--overhead-only] [--isa-ab]
       ... bench_torch.py --scaling [--repeat 3] [--json bench/results/torch-scaling.json] [--quick]

Energies: N = 5000 nodes, T = 100 frames, K = 16, gaps 1,2,4, float32: node confidences + C-ARAP
+ LRM + ARAP, loss = sum of the three energies, backward to positions and raw quaternions, at 1
and 2 threads (torch.set_num_threads). The PyTorch baseline is tests/torch/torch_reference.py
(vectorised autograd implementations of docs/math/energy.md), run eagerly and, as a third peer,
through torch.compile (torch 2.x; timed after its first call, which compiles and is reported on
its own; torch 1.x has no torch.compile and the row says so). DQB: 32768 points x 17 drivers
(K = 16), one query frame, against the autograd reference of docs/math/skin.md. Render: 100k
Gaussians at 320x240 through smg_torch; the dense pure-PyTorch reference
(tests/reference/gsplat_reference.py, every pixel against every Gaussian) is timed at a size it
fits in memory (2000 Gaussians, 160x120, float64 as the reference computes), where smg_torch
is timed too.
Overhead: smg_torch.carap and smg_torch.lrm forward + backward (autograd leaves, constant
confidences) against the bare C++ library call on the same tensors, timed in C++ with
std::chrono by smg_torch._library_seconds (zeroing the gradient buffers + the call), best of
--repeat runs taken interleaved, at 1 and 2 threads; overhead = binding / bare - 1.
Scaling (--scaling): the same energies at N x T in SCALING_SIZES (K = 16, gaps 1,2,4, float32, 2
threads) for smg, eager and compile: best-of---repeat time, ns per (edge, frame, gap) term
(carap_terms) and peak memory (RssPeak: resident-set growth over the calls); a PyTorch peer is
skipped at a size where the linear extrapolation from its largest measured size exceeds
--skip-seconds per call or the memory limit (scaling_table says which and why).
--isa-ab: two more rows per thread count, the fused step on smg_torch.isa's module (_C_avx2 on an AVX2 +
FMA CPU) and on the baseline module _C (SSE2), one call of each by turns per round (docs/torch.md
"Instruction sets"); nothing more where smg_torch.isa is "base".
Prints a markdown table; --json writes the same rows in Google Benchmark's JSON layout so that
bench/report.py puts them into docs/performance.md.
Floor (issue 59): beside each time, the case's floor on this machine, max(flops / peak, bytes /
bandwidth) with the counts of bench/floor.hpp (bench/torch/floor.py; the energy rows: the fused
step's count, the case being the same computation whichever peer runs it; the overhead rows:
C-ARAP's and LRM's own), and time / floor ("x floor"); the peak of all cores is read from
--floor-json FILE (bench_floor --json=FILE) or measured by the newest build/*/bench/bench_floor at
the start (n/a without either). DQB and render have no count yet ("n/a").
"""
import argparse
import datetime
import gc
import json
import math
import os
import re
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

sys.path.insert(0, HERE)
import floor  # noqa: E402  (bench/torch/floor.py: the floor beside each time)


def best_of(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def energy_scene(N, T, K, dtype=torch.float32, knn=None):
    """Positions [T, N, 3], raw quaternions [T, N, 4], graph indices [N, K] and weights [N, K]:
    the graph of smg.build_graph over the first 8 frames (trajectory KNN, uniform weights 1/K),
    or knn(frame-0 positions [N, 3], K) -> indices with weights 1/K."""
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
    if knn is None:
        graph = smg.build_graph(x[:8], k=K, gate=False)
        idx, w = graph.indices, graph.weights
    else:
        idx = knn(x[0], K)
        w = torch.full(idx.shape, 1.0 / K, dtype=torch.float64)
    return x.to(dtype), q.to(dtype), idx, w.to(dtype)


def grid_knn(p, K, chunk=8192):
    """Exact K nearest neighbours (self excluded, nearest first) of points p [N, 3] -> int64
    [N, K], through a voxel grid of about 2K points per cell: each point's candidates are the 27
    cells around its own; a row whose K-th distance exceeds the cell size h (a neighbour could lie
    outside them) is recomputed against every point. The scaling table's graph above GRAPH_MAX_N
    nodes, where smg.build_graph's trajectory KNN takes minutes on 2 cores."""
    N = p.shape[0]
    lo = p.min(0).values
    h = float(((p.max(0).values - lo).clamp_min(1e-9).prod() * 2 * K / N) ** (1 / 3))
    cell = ((p - lo) / h).floor().long()
    dims = cell.max(0).values + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = key.argsort()
    skey = key[order]
    counts = torch.bincount(skey, minlength=int(dims.prod()))
    rank = torch.arange(N) - (counts.cumsum(0) - counts)[skey]
    table = torch.full((counts.numel(), int(counts.max())), -1, dtype=torch.long)
    table[skey, rank] = order
    r = torch.tensor([-1, 0, 1])
    offs = torch.stack(torch.meshgrid(r, r, r, indexing="ij"), -1).reshape(27, 3)
    out = torch.empty(N, K, dtype=torch.long)
    for a in range(0, N, chunk):
        rows = torch.arange(a, min(N, a + chunk))
        nb = cell[rows, None] + offs
        inside = ((nb >= 0) & (nb < dims)).all(-1)
        nb = torch.minimum(nb.clamp(min=0), dims - 1)
        cand = table[(nb[..., 0] * dims[1] + nb[..., 1]) * dims[2] + nb[..., 2]]
        cand = torch.where(inside[..., None], cand, torch.full_like(cand, -1)).reshape(rows.numel(), -1)
        d = ((p[cand.clamp(min=0)] - p[rows, None]) ** 2).sum(-1)
        d = torch.where((cand < 0) | (cand == rows[:, None]), torch.full_like(d, float("inf")), d)
        dk, ik = d.topk(K, largest=False)
        out[rows] = cand.gather(1, ik)
        far = rows[dk[:, -1] > h * h]
        if far.numel():  # the rare row near a corner: against every point
            d = torch.cdist(p[far], p).pow(2)
            d[torch.arange(far.numel()), far] = float("inf")
            out[far] = d.topk(K, largest=False).indices
    return out


def energy_smg(xs, qs, idx, w, lrm=True):
    """The summed energy through smg_torch: confidences, then C-ARAP + LRM + ARAP (LRM left out
    with lrm=False, for a CUDA build without it)."""
    c = smg.node_confidences(xs, (idx, w))
    e = smg.carap(xs, qs, (idx, w), c) + smg.arap(xs, qs, (idx, w))
    return e + smg.lrm(xs, (idx, w), c) if lrm else e


def energy_ref(xs, qs, idx, w, lrm=True):
    """The same sum in pure PyTorch (tests/torch/torch_reference.py): what the eager peer runs and
    what torch.compile compiles."""
    c = ref.node_confidences(xs, idx, w)
    e = ref.carap(xs, qs, idx, w, c) + ref.arap(xs, qs, idx, w)
    return e + ref.lrm(xs, idx, w, c) if lrm else e


def fwd_bwd(energy, x, q, idx, w):
    """energy(...) on fresh leaves, then backward: (energy tensor, grad x, grad q). No host
    synchronisation (CUDA timings stay the device's)."""
    xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
    e = energy(xs, qs, idx, w)
    e.backward()
    return e.detach(), xs.grad, qs.grad


def energy_fused(xs, qs, idx, w):
    """The same sum through the fused step, smg_torch.regularizers (one pass; CPU or CUDA)."""
    return smg.regularizers(xs, qs, (idx, w), None, confidence=True, carap=True, arap=True, lrm=True).total


def energies_smg(x, q, idx, w):
    e, gx, gq = fwd_bwd(energy_smg, x, q, idx, w)
    return float(e), gx, gq


def energies_torch(x, q, idx, w):
    e, gx, gq = fwd_bwd(energy_ref, x, q, idx, w)
    return float(e), gx, gq


def no_compile_note():
    """What a compile row says where torch has no torch.compile (torch 1.x, e.g. Debian's 1.13)."""
    return f"torch.compile: not available in torch {torch.__version__}"


def compiled_peer(energy, call, repeat, timer, sync=lambda: None):
    """torch.compile(energy), timed after compilation: {"compile_s": the first call (tracing and
    compiling forward and backward, plus one run), "seconds": timer(call(fn), repeat) after one
    more warm-up call}, or {"note": no_compile_note()} without torch.compile. call(fn) runs one
    forward + backward of the compiled function; timer(f, repeat) -> best seconds. The compile
    cache is reset first, so that every size reports a full compile."""
    if not hasattr(torch, "compile"):
        return {"note": no_compile_note()}
    if hasattr(torch, "_dynamo"):
        torch._dynamo.reset()
    fn = torch.compile(energy)
    sync()
    t0 = time.perf_counter()
    call(fn)
    sync()
    compile_s = time.perf_counter() - t0
    call(fn)
    return {"compile_s": compile_s, "seconds": timer(lambda: call(fn), repeat)}


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


def energy_shape(idx, T, gaps=(1, 2, 4)):
    """bench/floor.hpp's Shape of the energies' scene: smg_torch's int64 indices, float32, no
    visibility, quaternion gradients."""
    return floor.Shape(T, idx.shape[0], int((idx >= 0).sum()), gaps=gaps, scalar=4, index=8, vis=0, rot_grad=4)


def overhead_work(name, shape):
    """The floor's work of an overhead row: C-ARAP with gradients or LRM with the exact gradient."""
    return floor.rigidity(shape, True, True) if name.startswith("C-ARAP") else floor.lrm(shape, 1)


def print_overhead(rows, repeat, m=None, shape=None):
    print(f"Binding overhead: smg_torch forward + backward against the bare C++ call (std::chrono in C++), "
          f"best of {repeat} interleaved, torch {torch.__version__}, {os.cpu_count()} CPUs\n")
    extra = m is not None and shape is not None
    print("| operation | smg_torch fwd+bwd | bare C++ call | overhead |"
          + (" floor | x floor (smg_torch) | x floor (C++) |" if extra else ""))
    print("|---|---:|---:|---:|" + ("---:|---:|---:|" if extra else ""))
    for name, a, b in rows:
        line = f"| {name} | {a * 1e3:.2f} ms | {b * 1e3:.2f} ms | {100 * (a / b - 1):+.1f} % |"
        if extra:
            work = overhead_work(name, shape)
            f, ra = floor.cells(m, work, a)
            line += f" {f} | {ra} | {floor.cells(m, work, b)[1]} |"
        print(line)


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


# ---- the scaling table (--scaling) ----------------------------------------------------------------
SCALING_SIZES = ((5000, 100), (20000, 100), (50000, 100), (100000, 100), (200000, 100), (50000, 400))
SCALING_QUICK = ((300, 10), (600, 10), (1200, 10), (600, 40))
GAPS = (1, 2, 4)
PEERS = ("smg", "eager", "compile")
# smg.build_graph (as the default run) up to this N: 11 s at 20k, 57 s at 50k on this 2-core
# machine, growing about as N^1.8 (~12 min at 200k); grid_knn above it.
GRAPH_MAX_N = 50000


def scaling_scene(N, T, K):
    return energy_scene(N, T, K, knn=None if N <= GRAPH_MAX_N else grid_knn)


def carap_terms(idx, T, gaps=GAPS):
    """Number of (edge, frame, gap) terms, as carap_term_count (include/smg/energy/carap.hpp):
    sum over gaps d of max(0, T - d), times E, the valid edges (indices >= 0). ARAP has as many;
    LRM (lrm_term_count) and the confidences have T * E (edge, frame) terms."""
    return sum(max(0, T - d) for d in gaps) * int((idx >= 0).sum())


def tensor_bytes(*tensors):
    return sum(t.numel() * t.element_size() for t in tensors)


try:
    import ctypes
    _libc = ctypes.CDLL("libc.so.6")
    _libc.malloc_trim  # glibc only
except (OSError, AttributeError):
    _libc = None


class RssPeak:
    """Peak resident-set growth of this process over some calls (CPU). reset() sets the kernel's
    peak (VmHWM) to the current resident set by writing 5 to /proc/self/clear_refs (Linux >= 4.0)
    and notes the resident set; peak() is VmHWM minus that. It counts pages touched: tensors,
    autograd's saved tensors, smg's scratch, allocator slack; the allocator's free memory is
    returned to the system (malloc_trim) before, but memory freed and reused within the calls is
    counted once, so it is the peak of live memory in pages, not the sum of the allocations. Where clear_refs cannot be written
    (ok = False) it is the growth of the process's lifetime peak, which hides a call smaller than
    an earlier one."""

    def __init__(self):
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
            self.ok = True
        except OSError:
            self.ok = False
        self.base = 0

    @staticmethod
    def _bytes(field):
        with open("/proc/self/status") as f:
            return int(re.search(rf"^{field}:\s+(\d+) kB", f.read(), re.M).group(1)) * 1024

    def reset(self):
        gc.collect()
        # Return the allocator's free memory to the system first: glibc raises its mmap threshold
        # (up to 32 MiB) after large frees, so an earlier peer's freed tensors would otherwise stay
        # resident and hide this one's (smg's gradients showed 0 MiB at 20k x 100 without it).
        if _libc is not None:
            _libc.malloc_trim(0)
        if self.ok:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
        self.base = self._bytes("VmRSS" if self.ok else "VmHWM")

    def peak(self):
        return max(0, self._bytes("VmHWM") - self.base)


def scaling_table(sizes, K, peers, limit_s, limit_bytes, scene=None, skippable=("eager", "compile")):
    """One dict per (N, T) of sizes: N, T, K, terms (carap_terms), inputs_bytes (x, q, graph) and,
    for each (name, measure) of peers, measure(x, q, idx, w) -> {"seconds": per call, "peak_bytes"
    [, "compile_s"]} or {"note": why there is no number}. A skippable peer is not run where the linear
    extrapolation (per term) of its time and peak from the last size it ran at exceeds limit_s
    per call or limit_bytes: its note gives the prediction. The scene is scaling_scene's unless
    scene(N, T, K) is given."""
    rows, per_term = [], {}
    for N, T in sizes:
        x, q, idx, w = (scene or scaling_scene)(N, T, K)
        terms = carap_terms(idx, T)
        row = {"N": N, "T": T, "K": K, "terms": terms, "inputs_bytes": tensor_bytes(x, q, idx, w),
               "work": floor.step(energy_shape(idx, T), True)}
        for name, measure in peers:
            if name in per_term and name in skippable:
                (s0, b0, at) = per_term[name]
                ps, pb = s0 * terms, b0 * terms
                if ps > limit_s or pb > limit_bytes:
                    row[name] = {"note": f"skipped: predicted {ps:.0f} s per call and {pb / 2**30:.1f} GiB peak "
                                         f"(linear in terms from {at}), limits {limit_s:.0f} s, "
                                         f"{limit_bytes / 2**30:.1f} GiB"}
                    print(f"  {N}x{T} {name}: {row[name]['note']}", flush=True)
                    continue
            try:
                r = measure(x, q, idx, w)
            except (RuntimeError, MemoryError) as e:  # CUDA's out of memory is a RuntimeError
                r = {"note": "failed: " + str(e).strip().splitlines()[0][:160]}
            row[name] = r
            if "seconds" in r:
                per_term[name] = (r["seconds"] / terms, r["peak_bytes"] / terms, f"{N}x{T}")
            print(f"  {N}x{T} {name}: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                                   for k, v in r.items()), flush=True)
        rows.append(row)
        del x, q, idx, w
        gc.collect()
    return rows


def _cells(r, terms):
    if "seconds" not in r:
        return ["skipped" if r["note"].startswith("skipped") else "n/a"] * 3
    return [f"{r['seconds'] * 1e3:.1f} ms", f"{r['seconds'] * 1e9 / terms:.2f}", f"{r['peak_bytes'] / 2**20:.0f}"]


def print_scaling(rows, title, memory, m=None):
    """The scaling table as markdown, then every peer's note (why a cell has no number)."""
    print(f"{title}\n\nns/term: time / (edge, frame, gap) terms, terms = sum over gaps d of (T - d) x "
          f"valid edges (carap_term_count). Peak: {memory}.\n")
    print("| N x T | terms | inputs [MiB] | smg | smg ns/term | smg peak [MiB] | eager | eager ns/term "
          "| eager peak [MiB] | compile (1st call) | compile | compile ns/term | compile peak [MiB] "
          "| eager / smg | compile / smg |" + (" floor | smg x floor |" if m else ""))
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|" + ("---:|---:|" if m else ""))
    notes = []
    for row in rows:
        terms, smg_r = row["terms"], row["smg"]
        cells = [f"{row['N']} x {row['T']}", f"{terms / 1e6:.1f} M", f"{row['inputs_bytes'] / 2**20:.0f}"]
        cells += _cells(smg_r, terms) + _cells(row["eager"], terms)
        c = row["compile"]
        cells.append(f"{c['compile_s']:.1f} s" if "compile_s" in c else "n/a")
        cells += _cells(c, terms)
        for name in ("eager", "compile"):
            r = row[name]
            ok = "seconds" in r and "seconds" in smg_r
            cells.append(f"{r['seconds'] / smg_r['seconds']:.1f}x" if ok else "")
        if m:
            cells += floor.cells(m, row["work"], smg_r.get("seconds"))
        print("| " + " | ".join(cells) + " |")
        notes += [(name, row[name]["note"], f"{row['N']} x {row['T']}") for name in PEERS if "note" in row[name]]
    # one line per peer and reason (torch.compile's absence is the same at every size)
    grouped = {}
    for name, note, size in notes:
        grouped.setdefault((name, note), []).append(size)
    for (name, note), sizes in grouped.items():
        print(f"- {name} at {', '.join(sizes)}: {note}")
    print()


def scaling_json(rows, threads, m=None):
    """Rows of the scaling table in bench/report.py's layout: real_time = smg's ms; pytorch_* = the
    eager peer (speedup = eager / smg, as torch.json's rows); compile_*; *_note where a peer has
    no number (NaN in its numeric fields)."""
    nan = float("nan")
    out = []
    for row in rows:
        terms = row["terms"]
        b = {"name": f"scaling: N={row['N']} T={row['T']} K={row['K']} float32, {threads} thread(s)",
             "run_type": "iteration", "time_unit": "ms", "terms": terms,
             "inputs_mib": row["inputs_bytes"] / 2**20}
        for name, prefix in (("smg", ""), ("eager", "pytorch_"), ("compile", "compile_")):
            r = row[name]
            ms_ = r["seconds"] * 1e3 if "seconds" in r else nan
            if name == "smg":
                b["real_time"] = b["cpu_time"] = ms_
            else:
                b[prefix + "ms"] = ms_
            b[prefix + "ns_per_term"] = ms_ * 1e6 / terms
            b[prefix + "peak_mib"] = r["peak_bytes"] / 2**20 if "peak_bytes" in r else nan
            if name == "compile":
                b["compile_time_s"] = r.get("compile_s", nan)
            if "note" in r:
                b[(prefix or "smg_") + "note"] = r["note"]
        b["speedup"] = b["pytorch_ms"] / b["real_time"]
        b["compile_speedup"] = b["compile_ms"] / b["real_time"]
        if m and m.floor_seconds(row["work"]) > 0:
            b["floor_ms"] = m.floor_seconds(row["work"]) * 1e3
            b["x_floor"] = b["real_time"] / b["floor_ms"]
        out.append(b)
    return out


def write_json(path, bench, repeat, extra=None):
    ctx = {"date": datetime.datetime.now().isoformat(timespec="seconds"),
           "num_cpus": os.cpu_count(), "mhz_per_cpu": "?",
           "library_build_type": "release (smg_torch extension, -O3)", "repeat": repeat,
           "torch": torch.__version__, "loadavg_start": " ".join(f"{v:.2f}" for v in os.getloadavg())}
    ctx.update(extra or {})
    with open(path, "w") as f:
        json.dump({"context": ctx, "benchmarks": bench}, f, indent=1, allow_nan=True)


def cpu_scaling(args):
    """--scaling on the CPU at 2 threads: smg, eager and compile at SCALING_SIZES (SCALING_QUICK
    with --quick); memory limit min(24 GiB, 90 % of the machine's RAM)."""
    m = floor.machine(args.floor_json)
    torch.set_num_threads(2)
    rss = RssPeak()
    load0 = " ".join(f"{v:.2f}" for v in os.getloadavg())

    def measure(call, warm):
        rss.reset()
        if warm:
            call()
        t = best_of(call, args.repeat)
        return {"seconds": t, "peak_bytes": rss.peak()}

    def peer_compile(x, q, idx, w):
        rss.reset()
        r = compiled_peer(energy_ref, lambda fn: fwd_bwd(fn, x, q, idx, w), args.repeat, best_of)
        if "seconds" in r:
            r["peak_bytes"] = rss.peak()
        return r

    peers = [("smg", lambda x, q, idx, w: measure(lambda: fwd_bwd(energy_smg, x, q, idx, w), True)),
             # no warm-up for eager (as the default run): nothing to warm but the allocator
             ("eager", lambda x, q, idx, w: measure(lambda: fwd_bwd(energy_ref, x, q, idx, w), False)),
             ("compile", peer_compile)]
    with open("/proc/meminfo") as f:
        ram = int(re.search(r"MemTotal:\s+(\d+) kB", f.read()).group(1)) * 1024
    limit_bytes = min(24 * 2**30, 0.9 * ram)
    t0 = time.perf_counter()
    rows = scaling_table(SCALING_QUICK if args.quick else SCALING_SIZES, 16, peers, args.skip_seconds,
                         limit_bytes)
    load1 = " ".join(f"{v:.2f}" for v in os.getloadavg())
    memory = ("resident-set growth over the calls (malloc_trim, then VmHWM reset through "
              "/proc/self/clear_refs; VmHWM after minus VmRSS before): the peak of live memory in "
              "pages, inputs excluded; memory freed and reused within a call counts once" if rss.ok else
              "growth of the process's peak resident set (ru_maxrss-like; a call smaller than an "
              "earlier one shows 0)")
    print_scaling(rows, f"Scaling, CPU, {torch.get_num_threads()} threads, best of {args.repeat} "
                        f"(smg after 1 warm-up, eager without, compile after its compile and 1 more call), "
                        f"torch {torch.__version__}, smg_torch.isa {smg.isa}, {os.cpu_count()} CPUs, load average {load0} before, "
                        f"{load1} after, {time.perf_counter() - t0:.0f} s", memory, m)
    print(m.describe() + "; the floor is the fused step's (bench/floor.hpp step), the same at every peer\n")
    if args.json:
        write_json(args.json, scaling_json(rows, 2, m), args.repeat,
                   {"smg_params": f"--scaling --repeat {args.repeat}, 2 threads",
                    "loadavg_start": load0, "loadavg_after": load1, **({"note": args.note} if args.note else {}), "peak_memory": memory,
                    "skip_limits": f"{args.skip_seconds:.0f} s per call, {limit_bytes / 2**30:.1f} GiB"})


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    ap.add_argument("--overhead-only", action="store_true",
                    help="only the binding-overhead rows (smg_torch against the bare C++ call)")
    ap.add_argument("--scaling", action="store_true",
                    help="only the scaling table (SCALING_SIZES; tiny sizes with --quick), 2 threads")
    ap.add_argument("--isa-ab", action="store_true",
                    help="the fused step also on the baseline module _C (SSE2), by turns with smg_torch.isa's module")
    ap.add_argument("--note", default=None,
                    help="--json: a caveat about this run's machine, stored in the context (report.py prints it)")
    ap.add_argument("--skip-seconds", type=float, default=120.0,
                    help="--scaling: skip a PyTorch peer whose predicted time per call exceeds this")
    ap.add_argument("--floor-json", default=None,
                    help="bench_floor --json=FILE's output: the peak behind the floor columns (default: run bench_floor now)")
    args = ap.parse_args()
    if args.scaling:
        cpu_scaling(args)
        return 0
    N, T, K, P, G, W, H = (5000, 100, 16, 32768, 100000, 320, 240)
    gs, ws, hs = 2000, 160, 120
    if args.quick:
        N, T, P, G, gs = 500, 20, 2048, 5000, 300
    old_threads = torch.get_num_threads()
    load0 = " ".join(f"{v:.2f}" for v in os.getloadavg())
    rows = []  # (name, smg seconds, torch seconds or None, compile peer dict or None)
    works = {}  # name -> (flops, bytes) of the floor; rows without a count have none

    m = floor.machine(args.floor_json)
    x, q, idx, w = energy_scene(N, T, K)
    shape = energy_shape(idx, T)
    step_work = floor.step(shape, True)
    if args.overhead_only:
        print_overhead(overhead_rows(x, q, idx, w, max(args.repeat, 5)), max(args.repeat, 5), m, shape)
        torch.set_num_threads(old_threads)
        return 0
    for threads in (1, 2):
        torch.set_num_threads(threads)
        energies_smg(x, q, idx, w)  # warm-up
        t_smg = best_of(lambda: energies_smg(x, q, idx, w), args.repeat)
        t_ref = best_of(lambda: energies_torch(x, q, idx, w), args.repeat)
        t_cmp = compiled_peer(energy_ref, lambda fn: fwd_bwd(fn, x, q, idx, w), args.repeat, best_of)
        rows.append((f"energies fwd+bwd (conf + C-ARAP + LRM + ARAP), N={N} T={T} K={K} float32, {threads} thread(s)",
                     t_smg, t_ref, t_cmp))
        works[rows[-1][0]] = step_work
        fwd_bwd(energy_fused, x, q, idx, w)  # warm-up
        t_fused = best_of(lambda: fwd_bwd(energy_fused, x, q, idx, w), args.repeat)
        rows.append((f"the same, fused (smg_torch.regularizers), {threads} thread(s)", t_fused, t_ref, t_cmp))
        works[rows[-1][0]] = step_work
        if args.isa_ab and smg.isa != "base":
            # the fused step on both modules by turns (each round one call of each)
            base_ops, t_a, t_b = smg._operators_from(None), float("inf"), float("inf")
            for _ in range(args.repeat):
                t_a = min(t_a, best_of(lambda: fwd_bwd(energy_fused, x, q, idx, w), 1))
                with smg._operators_in_use(base_ops):
                    t_b = min(t_b, best_of(lambda: fwd_bwd(energy_fused, x, q, idx, w), 1))
            rows.append((f"the same, fused, {smg.isa} by turns with the next row, {threads} thread(s)", t_a, t_ref,
                         None))
            works[rows[-1][0]] = step_work
            rows.append((f"the same, fused, baseline module _C (SSE2), {threads} thread(s)", t_b, t_ref, None))
            works[rows[-1][0]] = step_work
    overhead = overhead_rows(x, q, idx, w, max(args.repeat, 5))
    e1, gx1, gq1 = energies_smg(x, q, idx, w)
    e2, gx2, gq2 = energies_torch(x, q, idx, w)
    e3, gx3, gq3 = fwd_bwd(energy_fused, x, q, idx, w)
    agree = (f"float32 agreement: energy {abs(e1 - e2) / abs(e2):.1e}, grad x {rel(gx1, gx2):.1e}, grad q {rel(gq1, gq2):.1e}; "
             f"fused against eager: energy {abs(float(e3) - e2) / abs(e2):.1e}, grad x {rel(gx3, gx2):.1e}, "
             f"grad q {rel(gq3, gq2):.1e}")

    torch.set_num_threads(2)
    s = skin_scene(N, T, K, P)
    dqb_run(smg, s)
    t_smg = best_of(lambda: dqb_run(smg, s), args.repeat)
    t_ref = best_of(lambda: dqb_run(ref, s), args.repeat)
    rows.append((f"DQB fwd+bwd, P={P} points x {K + 1} drivers, 1 query frame, float32, 2 threads", t_smg, t_ref, None))

    t, bg = render_scene(G, W, H, torch.float32)
    render_run("smg", t, bg, W, H)
    t_smg = best_of(lambda: render_run("smg", t, bg, W, H), args.repeat)
    rows.append((f"render fwd+bwd, {G} Gaussians, {W}x{H}, float32, 2 threads", t_smg, None, None))
    # the dense reference computes in float64 (gsplat_reference.py sets the default dtype)
    t, bg = render_scene(gs, ws, hs, torch.float64)
    t_smg = best_of(lambda: render_run("smg", t, bg, ws, hs), args.repeat)
    t_ref = best_of(lambda: render_run("ref", t, bg, ws, hs), args.repeat)
    rows.append((f"render fwd+bwd, {gs} Gaussians, {ws}x{hs}, float64, 2 threads", t_smg, t_ref, None))
    torch.set_num_threads(old_threads)
    load1 = " ".join(f"{v:.2f}" for v in os.getloadavg())

    print(f"smg_torch vs pure-PyTorch autograd (eager) and torch.compile of the same PyTorch code, best of "
          f"{args.repeat}, torch {torch.__version__}, smg_torch.isa {smg.isa}, {os.cpu_count()} CPUs, load average {load0} before, "
          f"{load1} after\n")
    print("| operation | smg_torch | PyTorch autograd | speed-up | torch.compile (compile time) | speed-up "
          "| floor | smg x floor | autograd x floor | compile x floor |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, a, b, c in rows:
        cells = [name, f"{a * 1e3:.1f} ms"]
        cells += ([f"{b * 1e3:.1f} ms", f"{b / a:.1f}x"] if b else
                  ["n/a (dense reference: H*W*G = %.1e pairs)" % (W * H * G), ""])
        if c is None:
            cells += ["", ""]
        elif "seconds" in c:
            cells += [f"{c['seconds'] * 1e3:.1f} ms ({c['compile_s']:.1f} s)", f"{c['seconds'] / a:.1f}x"]
        else:
            cells += [c["note"], ""]
        work = works.get(name)
        cells += list(floor.cells(m, work, a))
        cells.append(floor.cells(m, work, b)[1] if b else "")
        cells.append(floor.cells(m, work, c["seconds"])[1] if c and "seconds" in c else "")
        print("| " + " | ".join(cells) + " |")
    print(f"\n{m.describe()}; the energy rows' floor is the fused step's count (bench/floor.hpp step), "
          f"the same for every peer; DQB and render: no count (n/a)")
    print(f"\n{agree}\n")
    print_overhead(overhead, max(args.repeat, 5), m, shape)
    if args.json:
        bench = []
        for name, a, b, c in rows:
            entry = {"name": name, "run_type": "iteration", "iterations": args.repeat,
                     "real_time": a * 1e3, "cpu_time": a * 1e3, "time_unit": "ms"}
            entry["pytorch_ms"] = b * 1e3 if b else float("nan")
            entry["speedup"] = b / a if b else float("nan")
            if c is not None and "seconds" in c:
                entry.update(compile_ms=c["seconds"] * 1e3, compile_time_s=c["compile_s"],
                             compile_speedup=c["seconds"] / a)
            elif c is not None:
                entry["compile_note"] = c["note"]  # no number where torch has no torch.compile
            if name in works and m.floor_seconds(works[name]) > 0:
                entry["floor_ms"] = m.floor_seconds(works[name]) * 1e3
                entry["x_floor"] = entry["real_time"] / entry["floor_ms"]
            bench.append(entry)
        for name, a, b in overhead:
            bench.append({"name": "overhead: " + name, "run_type": "iteration", "iterations": max(args.repeat, 5),
                          "real_time": a * 1e3, "cpu_time": a * 1e3, "time_unit": "ms",
                          "library_ms": b * 1e3, "overhead_percent": 100 * (a / b - 1)})
        write_json(args.json, bench, args.repeat, dict({"loadavg_start": load0, "loadavg_after": load1},
                                                       **({"note": args.note} if args.note else {})))
    return 0


if __name__ == "__main__":
    sys.exit(main())
