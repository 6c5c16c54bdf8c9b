#!/usr/bin/env python3
"""smg_torch.compat against the upstream loss written in plain PyTorch (CPU): forward + backward,
best of --repeat runs, and peak memory.

usage: PYTHONPATH=<build>/python /usr/bin/python3 bench/torch/bench_compat.py [--repeat 10]
           [--threads 2] [--json FILE] [--quick] [--device cuda] [--cases TEXT] [--isa-ab]

Shape of Motion's track smoothness (flow3d/trainer.py): means [G, 3, B, 3] (the Gaussians'
positions at t − 1, t, t + 1 for B batch frames), loss = mean ‖2 x_t − x_{t−1} − x_{t+1}‖ over
G·B (the trainer then scales it by 0.5 · w_smooth_tracks), G = 40 000, T = 3, B = 8, float32:
smg_torch.compat.som_accel(means) against the same expression in torch
((2 m[:, 1:-1] − m[:, :-2] − m[:, 2:]).norm(dim=-1).mean(), eager), each with backward to
means (a leaf; its .grad is dropped between runs). Also the initial optimisation's
compute_accel_loss on tracks [G, T, 3] with T = 30.

MoSca's photometric stage (lib_mosca/photo_recon.py): a window of T' = 25 frames, M = 10 000
nodes, K = 16 (self + 15), shifts [1, 3, 6] with weights [0.6, 0.3, 0.1], reduce "mean", one
coarse level (every node to its 8 nearest of a third, detach_nn), loss = 10·coord + 10·len:
smg_torch.compat.mosca_arap against MoSca's compute_arap_loss as a plain-torch reading
(tests/torch/test_compat.py's mosca_arap_torch, eager), and mosca_vel_acc (the sum of its four
losses) against compute_vel_acc_loss's reading; backward to the positions and raw quaternions. Time: best of --repeat calls at
torch.set_num_threads(--threads), the peers by turns in each round. Peak: resident-set growth over one call
(bench_torch.RssPeak: pages touched, the inputs excluded, the gradient included; smg's
workspace, kept between calls, is not counted once warm).
Dynamic 3D Gaussians (train.py get_loss, t >= 1): N = 100 000 foreground Gaussians, K = 20,
loss = 4 rigid + 4 rot + 2 iso: smg_torch.compat.d3dgs_losses against the upstream expressions
(tests/torch/test_compat_d3dgs.py's d3dgs_torch, eager).
DreamScene4D (gs_renderer_4d.py render_flow): N = 50 000 Gaussians, K = 16 (precompute_nn's
table: smg_torch.knn_points with self, weights exp(−10 d)), loss = scale + rigidity, backward to
all six inputs: smg_torch.compat.ds4d_losses against tests/torch/test_compat_ds4d.py's ds4d_torch
(eager; its weights float32 here, where upstream's numpy weights are float64). No floor count.
Dynamic Gaussian Marbles (src/models/gaussians.py): N = 100 000, the adjacent isometry on frnn's table (K = 24,
r = 0.3, self included; compat.frnn_knn) over a mask of 70 % of the Gaussians, loss = errs.mean(), and the
instance isometry on 2 × 4096 drawn pairs: marbles_isometry and marbles_global_rigid against
tests/torch/test_compat_marbles.py's readings. DynOMo (src/utils/losses.py physics_based_losses): N = 100 000,
K = 20 (o3d_knn's table, weights exp(−2000 d²)), loss = rigid + rot + iso, backward to the means and raw
rotations: dynomo_losses against tests/torch/test_compat_dynomo.py's reading. SC-GS (utils/deform_utils.py
cal_arap_error): 4 096 nodes, K = 10, two times: scgs_arap(sample_num=None) against the reading that sums
every node (tests/torch/test_compat_scgs.py). No floor count for these four.
--isa-ab: beside smg (the module smg_torch.isa names: _C_avx2 on an AVX2 + FMA CPU), the peer "smg base",
the same calls on the baseline module _C (SSE2), by turns in each round (docs/torch.md "Instruction sets").
--quick: G = 4 000, M = 1 000, N = 10 000 (512 SC-GS nodes), 3 repeats (a smoke run). Prints a markdown table; --json writes the rows.
--device cuda (smg_torch built with its CUDA operators, docs/torch.md): the same cases on the GPU, time by
CUDA events (best of --repeat after two warm-ups), peak = torch.cuda.max_memory_allocated growth over one
call (the inputs excluded), and a third peer, torch.compile of the upstream expression (timed after its first
call, whose seconds are reported as compile_s).
Floor (CPU, issue 59): beside each time, the case's floor on this machine, max(flops / peak, bytes /
bandwidth), with the counts of bench/floor.hpp (som_accel, mosca_arap, mosca_vel_acc, d3dgs; through
bench/torch/floor.py) and the peak of all cores from --floor-json FILE (bench_floor --json=FILE) or from
the newest build/*/bench/bench_floor run at the start (n/a without either); "x floor" = time / floor.
The --device cuda table has no floor column.
"""
import argparse
import gc
import json
import os
import sys
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
# The upstream readings the tests check smg against (one copy of each, in the tests).
sys.path.insert(0, os.path.join(HERE, "..", "..", "tests", "torch"))

import bench_torch  # noqa: E402  (RssPeak)
from smg_torch.compat import (d3dgs_losses, ds4d_losses, dynomo_losses, marbles_global_rigid,  # noqa: E402
                               marbles_isometry, mosca_arap, mosca_vel_acc, scgs_arap, som_accel)
from test_compat import GAMMAS, SHIFTS, mosca_arap_torch, mosca_scene, mosca_vel_acc_torch  # noqa: E402
from test_compat_d3dgs import d3dgs_torch  # noqa: E402
from test_compat_ds4d import ds4d_torch  # noqa: E402
from test_compat_dynomo import dynomo_torch  # noqa: E402
from test_compat_marbles import global_rigid_torch, isometry_torch  # noqa: E402
from test_compat_scgs import cal_arap_error_torch, connectivity  # noqa: E402
import floor  # noqa: E402
import smg_torch as smg  # noqa: E402  (smg.isa, printed with the table)
from smg_torch import knn_points  # noqa: E402  (bench/torch/floor.py: the floor beside each time)
from smg_torch.compat import frnn_knn  # noqa: E402

WORK = {}  # case name -> (flops, bytes) of its floor (bench/floor.hpp), filled by the case builders


def som_accel_torch(m):
    """The upstream expression, eager PyTorch."""
    return (2 * m[:, 1:-1] - m[:, :-2] - m[:, 2:]).norm(dim=-1).mean()


def call(fn, xs):
    for x in xs:
        x.grad = None
    with smg._operators_in_use(getattr(fn, "smg_ops", None)):
        fn(*xs).backward()


def on_baseline(fn):
    """fn with smg_torch's baseline module (_C) in place of _C_avx2, forward and backward (the
    --isa-ab peer "smg base")."""
    def run(*xs):
        return fn(*xs)
    run.smg_ops = smg._operators_from(None)
    return run


def best_times(peers, xs, repeat):
    """Best seconds of fn(*xs).backward() over `repeat` rounds per peer, the peers taken by turns
    in each round (a load change on a shared machine then hits both)."""
    for _, fn in peers:
        call(fn, xs)  # warm-up (allocator, thread pool, smg's workspace)
    best = {name: float("inf") for name, _ in peers}
    for _ in range(repeat):
        for name, fn in peers:
            t0 = time.perf_counter()
            call(fn, xs)
            best[name] = min(best[name], time.perf_counter() - t0)
    for x in xs:
        x.grad = None
    return best


def peak(fn, xs):
    """Resident-set growth of one call (after a warm-up call)."""
    gc.collect()
    rss = bench_torch.RssPeak()
    rss.reset()
    call(fn, xs)
    p = rss.peak()
    for x in xs:
        x.grad = None
    return p


def cuda_best(fn, xs, repeat):
    """Best seconds of fn(*xs).backward() by CUDA events over `repeat` runs, after two warm-ups."""
    call(fn, xs)
    call(fn, xs)
    times = []
    for _ in range(repeat):
        a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        a.record()
        call(fn, xs)
        b.record()
        torch.cuda.synchronize()
        times.append(a.elapsed_time(b) * 1e-3)
    for x in xs:
        x.grad = None
    return min(times)


def cuda_peak(fn, xs):
    """Growth of torch.cuda.max_memory_allocated over one call (the gradients included)."""
    for x in xs:
        x.grad = None
    torch.cuda.synchronize()
    base = torch.cuda.memory_allocated()
    torch.cuda.reset_peak_memory_stats()
    call(fn, xs)
    torch.cuda.synchronize()
    p = torch.cuda.max_memory_allocated() - base
    for x in xs:
        x.grad = None
    return p


def mosca_cases(M, g, device="cpu"):
    """MoSca's photometric window: (name, shape, inputs, smg loss, torch loss)."""
    xyz, q, ti, mask, lv = mosca_scene(T=25, M=M, K=16, seed=0, dtype=torch.float32)
    xyz, q, ti, mask = (t.to(device) for t in (xyz, q, ti, mask))
    lv = tuple((e.to(device), w.to(device), mu, dn, ds) for e, w, mu, dn, ds in lv)
    x, r = xyz.requires_grad_(), q.requires_grad_()

    def arap_smg(x, r):
        c, l = mosca_arap(x, r, ti, mask, SHIFTS, GAMMAS, levels=lv)
        return 10 * c + 10 * l

    def arap_torch(x, r):
        c, l = mosca_arap_torch(x, r, ti, mask, SHIFTS, GAMMAS, levels=lv)
        return 10 * c + 10 * l

    # the floor's edges: every weighted neighbour k >= 1 of topo_ind (the self entry is zero) and
    # every coarse edge of non-zero weight; the graph as the call takes it (int64, bool, float32)
    E = int(mask[:, 1:].sum()) + sum(int((w_ > 0).sum()) for _, w_, _, _, _ in lv)
    WORK["MoSca ARAP, one coarse level"] = floor.mosca_arap(
        25, M, E, sum(25 - s for s in SHIFTS), ti.numel() * 8 + mask.numel() + sum(e.numel() * 8 + w_.numel() * 4
                                                                                   for e, w_, _, _, _ in lv))
    WORK["MoSca vel/acc"] = floor.mosca_vel_acc(25, M)
    return [("MoSca ARAP, one coarse level", [25, M, 16], [x, r], arap_smg, arap_torch),
            ("MoSca vel/acc", [25, M], [x, r], lambda x, r: sum(mosca_vel_acc(x, r)),
             lambda x, r: sum(mosca_vel_acc_torch(x, r)))]


def d3dgs_cases(N, device="cpu"):
    """Dynamic 3D Gaussians' timestep t >= 1: N foreground Gaussians, K = 20 neighbours (here the 20
    nearest in a sorted order along x, i ± 1 .. 10: a KNN-like graph without an O(N²) search),
    weights exp(−2000 d²), loss = 4 rigid + 4 rot + 2 iso; backward to fg_pts and fg_rot."""
    g = torch.Generator().manual_seed(1)
    pts = torch.rand(N, 3, generator=g)
    pts = pts[pts[:, 0].argsort()]
    off = torch.tensor([o for o in range(-10, 11) if o != 0])
    i = torch.arange(N)[:, None]
    idx = (i + off[None, :])
    idx = torch.where(idx < 0, idx + 21, idx)
    idx = torch.where(idx >= N, idx - 21, idx)
    d0 = (pts[idx] - pts[:, None]).norm(dim=-1)
    w = torch.exp(-2000 * d0 ** 2)
    prev_rot = torch.nn.functional.normalize(torch.randn(N, 4, generator=g), dim=-1)
    fg_rot = torch.nn.functional.normalize(prev_rot + 0.05 * torch.randn(N, 4, generator=g), dim=-1)
    prev_pts = pts + 0.01 * torch.randn(N, 3, generator=g)
    fg_pts = prev_pts + 0.01 * torch.randn(N, 3, generator=g)
    dev = lambda t: t.to(device)  # noqa: E731
    prev_pts, prev_rot, idx, w, d0 = map(dev, (prev_pts, prev_rot, idx, w, d0))
    x, r = dev(fg_pts).requires_grad_(), dev(fg_rot).requires_grad_()

    def loss(fn):
        return lambda x, r: sum(c * l for c, l in zip((4.0, 4.0, 2.0), fn(x, r, prev_pts, prev_rot, idx, w, d0)))

    WORK["D3DGS rigid + rot + iso"] = floor.d3dgs(N, 20)
    return [("D3DGS rigid + rot + iso", [N, 20], [x, r], loss(d3dgs_losses), loss(d3dgs_torch))]


def ds4d_cases(N, device="cpu"):
    """DreamScene4D's render_flow losses at N Gaussians, K = 16 (see the module docstring)."""
    g = torch.Generator().manual_seed(2)
    pos_prev = torch.rand(N, 3, generator=g)
    pos_curr = pos_prev + 0.01 * torch.randn(N, 3, generator=g)
    rot_prev = torch.randn(N, 4, generator=g) * 0.2 + torch.tensor([1.0, 0, 0, 0])
    rot_curr = rot_prev + 0.05 * torch.randn(N, 4, generator=g)
    sc_base = torch.randn(N, 3, generator=g) - 4
    sc_prev = sc_base + 0.1 * torch.randn(N, 3, generator=g)
    d2, idx = knn_points(pos_prev, 16)
    w = torch.exp(-10 * d2.sqrt())
    xs = [t.to(device).requires_grad_() for t in (pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base)]
    idx, w = idx.to(device), w.to(device)

    def loss(fn):
        return lambda *v: sum(fn(*v, idx, w))

    return [("DreamScene4D scale + rigidity", [N, 16], xs, loss(ds4d_losses), loss(ds4d_torch))]


def marbles_cases(N, device="cpu"):
    """Dynamic Gaussian Marbles at N Gaussians: the adjacent isometry on frnn's table (K = 24,
    r = 0.3, self included) over a mask of 70 %, errs.mean(), and the instance isometry on 4096
    pairs of each of two halves (module docstring)."""
    g = torch.Generator().manual_seed(3)
    src = torch.rand(N, 3, generator=g)
    xyz = src + 0.01 * torch.randn(N, 3, generator=g)
    mask = torch.rand(N, generator=g) < 0.7
    _, idx = frnn_knn(src[mask], 24, 0.3)
    valid = idx[0] != -1
    p = torch.arange(int(mask.sum())).repeat_interleave(24)[valid.flatten()].int()
    k = idx[0][valid].int()
    src, mask, p, k = (t.to(device) for t in (src, mask, p, k))
    x = xyz.to(device).requires_grad_()
    t = (xyz + 0.02 * torch.randn(N, 3, generator=g)).to(device).requires_grad_()
    half = N // 2
    i1 = torch.cat([torch.randperm(half, generator=g)[:4096], half + torch.randperm(N - half, generator=g)[:4096]])
    i2 = torch.cat([torch.randperm(half, generator=g)[:4096], half + torch.randperm(N - half, generator=g)[:4096]])
    i1, i2 = i1.to(device), i2.to(device)
    return [("Marbles adjacent isometry", [N, 24], [x], lambda v: marbles_isometry(v, src, p, k, mask).mean(),
             lambda v: isometry_torch(v, src, p.long(), k.long(), mask, False).mean()),
            ("Marbles instance isometry", [N, 8192], [t], lambda v: marbles_global_rigid(src, v, i1, i2),
             lambda v: global_rigid_torch(src, v, i1, i2))]


def dynomo_cases(N, device="cpu"):
    """DynOMo's physics-based losses at N Gaussians, K = 20 (o3d_knn's table, weights
    exp(−2000 d²)), loss = rigid + rot + iso, backward to the means and raw rotations."""
    g = torch.Generator().manual_seed(4)
    prev = torch.rand(N, 3, generator=g)
    curr = prev + 0.005 * torch.randn(N, 3, generator=g)
    prev_rot = torch.randn(N, 4, generator=g) * 0.3 + torch.tensor([1.5, 0, 0, 0])
    curr_rot = prev_rot + 0.05 * torch.randn(N, 4, generator=g)
    d2, idx = knn_points(prev, 21)
    s = torch.arange(N).repeat_interleave(20)
    n = idx[:, 1:].flatten()
    w = torch.exp(-2000 * d2[:, 1:].flatten())
    first = prev + 0.01 * torch.randn(N, 3, generator=g)
    off0 = first[s] - first[n]
    prev, prev_rot, s, n, w, off0 = (t.to(device) for t in (prev, prev_rot, s, n, w, off0))
    xs = [curr.to(device).requires_grad_(), curr_rot.to(device).requires_grad_()]

    def loss(fn):
        return lambda x, q: sum(fn(x, q, prev, prev_rot, s, n, w, off0))

    return [("DynOMo rigid + rot + iso", [N, 20], xs, loss(dynomo_losses), loss(dynomo_torch))]


def scgs_cases(M, device="cpu"):
    """SC-GS's ARAP at M control nodes, K = 10, two times (ControlNodeWarp.arap_loss): every node
    (sample_num=None) against cal_arap_error's reading summing every node (tests/torch/test_compat_scgs.py)."""
    g = torch.Generator().manual_seed(5)
    x0 = torch.rand(M, 3, generator=g, dtype=torch.float64)
    x1 = x0 + 0.01 * torch.randn(M, 3, generator=g, dtype=torch.float64)
    ii, jj, nn, _ = connectivity(x0, radius=0.1)
    ii, jj, nn = (t.to(device) for t in (ii, jj, nn))
    x = torch.stack([x0, x1]).float().to(device).requires_grad_()
    return [("SC-GS ARAP, every node", [M, 10], [x], lambda v: scgs_arap(v, ii, jj, nn, 10, sample_num=None),
             lambda v: cal_arap_error_torch(v, ii, jj, nn, 10))]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--cases", default="", help="run only the cases whose name contains this text")
    ap.add_argument("--isa-ab", action="store_true",
                    help="a third peer, 'smg base': smg on the baseline module _C (SSE2), by turns with 'smg' "
                         "(smg_torch.isa's module) in each round")
    ap.add_argument("--floor-json", default=None,
                    help="bench_floor --json=FILE's output: the peak behind the floor columns (default: run bench_floor now)")
    a = ap.parse_args()
    if a.device == "cuda":
        import smg_torch
        if not (torch.cuda.is_available() and smg_torch.has_cuda):
            sys.exit("bench_compat: error: --device cuda needs a GPU and smg_torch built with CUDA (docs/torch.md)")
        return main_cuda(a)
    repeat = 3 if a.quick else a.repeat
    G = 4000 if a.quick else 40000
    torch.set_num_threads(a.threads)
    g = torch.Generator().manual_seed(0)
    cases = []
    for name, shape in [("SoM tracks [G, 3, B, 3]", (G, 3, 8, 3)), ("SoM init tracks [G, T, 3]", (G, 30, 3))]:
        x = (torch.randn(shape, generator=g).cumsum(1) * 0.1).float().requires_grad_()
        cases.append((name, list(shape), [x], som_accel, som_accel_torch))
        # second differences: [G, 3, B, 3] one per (g, b), its points its own; [G, T, 3] T - 2 per g, shared
        WORK[name] = (floor.som_accel(G * shape[2], x.numel(), False) if len(shape) == 4 else
                      floor.som_accel(G * (shape[1] - 2), x.numel(), True))
    m = floor.machine(a.floor_json)
    cases += mosca_cases(1000 if a.quick else 10000, g)
    cases += d3dgs_cases(10000 if a.quick else 100000)
    cases += ds4d_cases(5000 if a.quick else 50000)
    cases += marbles_cases(10000 if a.quick else 100000)
    cases += dynomo_cases(10000 if a.quick else 100000)
    cases += scgs_cases(512 if a.quick else 4096)
    cases = [c for c in cases if a.cases in c[0]]
    rows = []
    for name, shape, xs, f_smg, f_ref in cases:
        e_smg, e_ref = float(f_smg(*xs)), float(f_ref(*xs))
        peers = (("smg", f_smg),) + ((("smg base", on_baseline(f_smg)),) if a.isa_ab else ()) + (("torch", f_ref),)
        best = best_times(peers, xs, repeat)
        for peer, fn in peers:
            rows.append(dict(case=name, shape=shape, peer=peer, seconds=best[peer], peak_bytes=peak(fn, xs),
                             input_bytes=sum(x.numel() * x.element_size() for x in xs),
                             rel_diff=abs(e_smg - e_ref) / abs(e_ref)))
    print(f"threads {a.threads}, float32, best of {repeat}, forward + backward, smg_torch.isa {smg.isa}; "
          "peak = resident-set growth of one call")
    print("| case | shape | peer | ms | peak MiB | input MiB | energy rel. diff smg/torch | floor ms | x floor |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        fl, ratio = floor.cells(m, WORK.get(r["case"]), r["seconds"])
        r["floor_ms"] = m.floor_seconds(WORK[r["case"]]) * 1e3 if r["case"] in WORK else None
        print(f"| {r['case']} | {r['shape']} | {r['peer']} | {r['seconds'] * 1e3:.2f} | "
              f"{r['peak_bytes'] / 2**20:.1f} | {r['input_bytes'] / 2**20:.1f} | {r['rel_diff']:.1e} | "
              f"{fl.replace(' ms', '')} | {ratio} |")
    print(m.describe())
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(threads=a.threads, repeat=repeat, torch=torch.__version__, isa=smg.isa, floor=m.describe(),
                           rows=rows), f,
                      indent=1)


def main_cuda(a):
    """The cases on the GPU: smg, eager torch and torch.compile of the upstream expression."""
    repeat = 3 if a.quick else a.repeat
    G = 4000 if a.quick else 40000
    g = torch.Generator().manual_seed(0)
    cases = []
    for name, shape in [("SoM tracks [G, 3, B, 3]", (G, 3, 8, 3)), ("SoM init tracks [G, T, 3]", (G, 30, 3))]:
        x = (torch.randn(shape, generator=g).cumsum(1) * 0.1).float().cuda().requires_grad_()
        cases.append((name, list(shape), [x], som_accel, som_accel_torch))
    cases += mosca_cases(1000 if a.quick else 10000, g, "cuda")
    cases += d3dgs_cases(10000 if a.quick else 100000, "cuda")
    cases += ds4d_cases(5000 if a.quick else 50000, "cuda")
    cases += marbles_cases(10000 if a.quick else 100000, "cuda")
    cases += dynomo_cases(10000 if a.quick else 100000, "cuda")
    cases += scgs_cases(512 if a.quick else 4096, "cuda")
    cases = [c for c in cases if a.cases in c[0]]
    rows = []
    for name, shape, xs, f_smg, f_ref in cases:
        e_smg, e_ref = float(f_smg(*xs)), float(f_ref(*xs))
        row = dict(case=name, shape=shape, input_bytes=sum(x.numel() * x.element_size() for x in xs),
                   rel_diff=abs(e_smg - e_ref) / abs(e_ref))
        for peer, fn in (("smg", f_smg), ("torch", f_ref)):
            rows.append(dict(row, peer=peer, seconds=cuda_best(fn, xs, repeat), peak_bytes=cuda_peak(fn, xs)))
        try:
            torch._dynamo.reset()
            fc = torch.compile(f_ref)
            torch.cuda.synchronize()
            t0 = time.perf_counter()
            call(fc, xs)
            torch.cuda.synchronize()
            compile_s = time.perf_counter() - t0
            rows.append(dict(row, peer="torch.compile", seconds=cuda_best(fc, xs, repeat),
                             peak_bytes=cuda_peak(fc, xs), compile_s=compile_s,
                             rel_diff=abs(e_smg - float(fc(*xs))) / abs(e_ref)))
        except Exception as e:  # noqa: BLE001  (a compile failure is reported as a row, not a crash)
            rows.append(dict(row, peer="torch.compile", seconds=float("nan"), peak_bytes=0,
                             note=f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"))
    print(f"{torch.cuda.get_device_name()}, torch {torch.__version__}, float32, best of {repeat} (CUDA events), "
          "forward + backward; peak = max_memory_allocated growth of one call")
    print("| case | shape | peer | ms | peak MiB | input MiB | energy rel. diff to smg | note |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        note = r.get("note", f"compile {r['compile_s']:.1f} s" if "compile_s" in r else "")
        print(f"| {r['case']} | {r['shape']} | {r['peer']} | {r['seconds'] * 1e3:.3f} | "
              f"{r['peak_bytes'] / 2**20:.1f} | {r['input_bytes'] / 2**20:.1f} | {r['rel_diff']:.1e} | {note} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(device=torch.cuda.get_device_name(), repeat=repeat, torch=torch.__version__,
                           rows=rows), f, indent=1)


if __name__ == "__main__":
    main()
