#!/usr/bin/env python3
"""scripts/defaults_study.py's rule on hand-made runs: a candidate becomes the default only when it
is never worse beyond noise (query EPE or masked PSNR) in any cell and better (query EPE) in one."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
import defaults_study as ds  # noqa: E402


def run(epe, psnr, hidden=None):
    parts = {"all": {"epe": epe}, "visible": {"epe": epe}}
    if hidden is not None:
        parts["hidden"] = {"epe": hidden}
    return {"epe_query": {"stage2": parts}, "test_psnr_masked": psnr}


def runs(cell_changes, seeds=("0", "1", "2", "3")):
    """res[(scene, failures, seed, tag)] with the candidate 'c' changed by (d_epe_m, d_psnr) per cell,
    plus a seed-dependent spread so that intervals are finite."""
    res = {}
    for k, (cell, (de, dp)) in enumerate(cell_changes.items()):
        for i, sd in enumerate(seeds):
            base_epe, base_psnr = 0.05 + 0.001 * k, 25.0
            jitter = 1e-4 * (i - 1.5)
            res[cell + (sd, ds.BASE)] = run(base_epe, base_psnr)
            res[cell + (sd, "c")] = run(base_epe + de + jitter, base_psnr + dp + 0.01 * (i - 1.5))
    return res


seeds = ["0", "1", "2", "3"]
a, b = ("standard", "off"), ("occluder", "off")
# Better in one cell, tie in the other: adopted.
res = runs({a: (-0.003, 0.0), b: (0.0, 0.0)})
rows, v = ds.table(res, [a, b], seeds, "c", ds.BASE)
assert v[(a, "epe")] == "better" and v[(b, "epe")] == "tie", v
assert ds.adopts(v), v
assert "–" in rows[2], "a part without samples (hidden) is shown as missing, not as 0"
# Better in one cell, worse beyond noise in another: refused.
res = runs({a: (-0.003, 0.0), b: (0.002, 0.0)})
_, v = ds.table(res, [a, b], seeds, "c", ds.BASE)
assert v[(b, "epe")] == "worse" and not ds.adopts(v), v
# Better 3D, worse images beyond noise: refused.
res = runs({a: (-0.003, -0.5), b: (0.0, 0.0)})
_, v = ds.table(res, [a, b], seeds, "c", ds.BASE)
assert v[(a, "psnr")] == "worse" and not ds.adopts(v), v
# Ties everywhere: not adopted (better nowhere).
res = runs({a: (0.0, 0.0), b: (0.0, 0.0)})
_, v = ds.table(res, [a, b], seeds, "c", ds.BASE)
assert not ds.adopts(v), v
assert abs(ds.mean_change(runs({a: (-0.002, 0.0), b: (0.0, 0.0)}), [a, b], seeds, "c", ds.BASE) + 1.0) < 1e-9
print("defaults_study rule: ok")
