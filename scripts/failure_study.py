#!/usr/bin/env python3
"""Where C-ARAP helps, judged by what users measure (docs/results.md, "C-ARAP across scenes and
tracker failures"; issues 25 and 33).

For every scene (standard, occluder, bending) and tracker-failure level (off, typical, double:
--tracker-failures, docs/trainer.md "Tracker failures") it runs smg_trainer on every seed:
  * stage 0 and stage 1 only (--stage2-iters 0) for four variants: no-carap (ARAP + LRM) and full
    (C-ARAP + LRM), smg-only (ARAP) and no-lrm (C-ARAP), the two pairs that isolate C-ARAP with and
    without LRM;
  * the full pipeline (default stage 2) of no-carap and full on the --stage2-scenes cells;
  * stage 1 of no-carap and full on the --holdout-seeds (seeds that no choice was made on).
(Until 2026-11-29 it also ran full with --alpha auto on the held-out seeds: a rule that picked
C-ARAP or plain ARAP from signals seen before stage 1. The defaults study removed it from the
trainer (docs/results.md, "What the trainer sees before stage 1"); the page's tables that report
it were written by that version of this script.)
Every run is scored by the 3D EPE of the kQueryCount surface query tracks that --export-dycheck
writes (metrics.json epe_query, after stage 1 and after stage 2: the metric Dycheck and
Shape-of-Motion report) and by node EPE (the error of the node trajectories, a diagnostic).
It writes, between the markers <!-- ladder:failure-study --> and <!-- /ladder:failure-study -->
of the results page, the paired differences C-ARAP − ARAP per cell (mean ± 95 % interval over the
seeds, and the seeds on which C-ARAP is better) by both metrics, the stage-2 table, the split of
the node-EPE difference (node_epe_split_stage1), and the run-time signals beside C-ARAP − ARAP.
Usage: scripts/failure_study.py [--seeds "0 1 2 3 4"] [--holdout-seeds "5 6 7 8 9"]
                                [--stage2-scenes "occluder bending"] [--jobs 2]
                                [--out build/failure_study] [--doc docs/results.md]
                                [--trainer build/release/examples/smg_trainer]
Without --trainer it first builds the trainer into build/release (scripts/build_trainer.sh).
A run whose metrics.json exists is not repeated (delete OUT to start over); a short canary run
first checks that the trainer still computes what made them (ladder_report.check_cache)."""
import concurrent.futures
import datetime
import json
import math
import os
import platform
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ladder_report import fmt, mean_ci, study_arguments, write_section  # noqa: E402

SCENES = ["standard", "occluder", "bending"]
FAILURES = ["off", "typical", "double"]
VARIANTS = ["no-carap", "full", "smg-only", "no-lrm"]
# The node-EPE split (evaluate.hpp, node_error_split): groups whose contributions sum to the total.
SPLITS = [(("failed", "clean"), "failed reports \\| clean samples"),
          (("conf_low", "conf_mid", "conf_high"), "c < 0.3 \\| 0.3–0.7 \\| ≥ 0.7"),
          (("driving", "idle"), "nodes driving queries \\| driving none")]


def extra_arguments(ap):
    ap.add_argument("--holdout-seeds", default="5 6 7 8 9",
                    help="seeds that C-ARAP − ARAP is confirmed on (the design tables use --seeds)")
    ap.add_argument("--stage2-scenes", default="occluder bending",
                    help="scenes whose cells also run the full pipeline (stage 2)")


def run(trainer, out, scene, failures, seed, variant, stage2=False):
    """One run's metrics.json."""
    tag = "_s2" if stage2 else ""
    d = os.path.join(out, f"{scene}_{failures}_{variant}{tag}_s{seed}")
    path = os.path.join(d, "metrics.json")
    if os.path.exists(path):
        return json.load(open(path))
    cmd = [trainer, "--scene", scene, "--tracker-failures", failures, "--seed", str(seed),
           "--variant", variant,
           "--threads", "1", "--no-pictures", "--no-view", "--quiet", "--out", d]
    if not stage2:
        cmd += ["--stage2-iters", "0", "--no-image-eval"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.load(open(path))


def signal(m, k):
    """Run-time signal k of metrics.json `m` as a float: the trainer writes null (NaN) when no
    node sample was observed."""
    v = m["signals"].get(k)
    return float("nan") if v is None else float(v)


def q1(m):
    return m["epe_query"]["stage1"]["all"]["epe"]


def q2(m):
    return m["epe_query"]["stage2"]["all"]["epe"]


def qhidden(m):
    return m["epe_query"]["stage1"]["hidden"]["epe"]


def node1(m):
    return m["epe_stage1"]


def paired(res, keys_a, keys_b, metric):
    """metric(a) − metric(b) per seed, in mm: mean ± 95 % interval and the seeds on which a is lower."""
    dd = [1e3 * (metric(res[ka]) - metric(res[kb])) for ka, kb in zip(keys_a, keys_b)]
    mu, half = mean_ci(dd)
    return mu, half, sum(1 for x in dd if x < 0), dd


def cell(res, scene, fl, seeds, a, b, metric, stage2=False):
    ka = [(scene, fl, sd, a, stage2) for sd in seeds]
    kb = [(scene, fl, sd, b, stage2) for sd in seeds]
    mu, half, wins, dd = paired(res, ka, kb, metric)
    return f"{fmt(mu, half, 2)} ({wins}/{len(seeds)})", mu, half, wins, dd


def split_contributions(m):
    """Each group's share of the node EPE after stage 1 (epe × samples / all samples), in mm."""
    sp = m["node_epe_split_stage1"]
    total = sum(sp[g]["samples"] for g in ("failed", "clean"))
    out = {}
    for groups, _ in SPLITS:
        for g in groups:
            e = sp[g]["epe"]
            out[g] = 0.0 if e is None else 1e3 * e * sp[g]["samples"] / total
    out["weighted"] = 1e3 * sp["weighted_epe"]
    return out


def main():
    a = study_arguments("build/failure_study", extra_arguments)
    seeds = a.seeds.split()
    hold = a.holdout_seeds.split()
    s2scenes = a.stage2_scenes.split()
    os.makedirs(a.out, exist_ok=True)
    keys = [(s, f, sd, v, False) for s in SCENES for f in FAILURES for sd in seeds for v in VARIANTS]
    keys += [(s, f, sd, v, False) for s in SCENES for f in FAILURES for sd in hold for v in ("no-carap", "full")]
    keys += [(s, f, sd, v, True) for s in s2scenes for f in FAILURES for sd in seeds for v in ("no-carap", "full")]
    with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
        futs = {k: ex.submit(run, a.trainer, a.out, *k) for k in keys}
        res = {k: f.result() for k, f in futs.items()}
    n = len(seeds)

    # 1. Stage 1, every cell, both metrics.
    rows = ["| scene | failures | ARAP + LRM query EPE (m) | **C-ARAP − ARAP, query EPE (mm)** | C-ARAP − ARAP, "
            "node EPE (mm) | query EPE, hidden samples (mm) | without LRM: query EPE (mm) | without LRM: node EPE (mm) | "
            "query EPE (mm), design and held-out seeds pooled |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for scene in SCENES:
        for fl in FAILURES:
            ref = [q1(res[(scene, fl, sd, "no-carap", False)]) for sd in seeds]
            cells = [fmt(*mean_ci(ref), 4)]
            for va, vb, met in (("full", "no-carap", q1), ("full", "no-carap", node1), ("full", "no-carap", qhidden),
                                ("no-lrm", "smg-only", q1), ("no-lrm", "smg-only", node1)):
                cells.append(cell(res, scene, fl, seeds, va, vb, met)[0])
            cells.append(cell(res, scene, fl, seeds + hold, "full", "no-carap", q1)[0])
            rows.append(f"| {scene} | {fl} | " + " | ".join(cells) + " |")

    # 2. The full pipeline on the stage-2 scenes.
    rows2 = ["| scene | failures | ARAP + LRM query EPE after stage 2 (m) | C-ARAP − ARAP, query EPE after stage 1 "
             "(mm) | **after stage 2 (mm)** | per seed after stage 2 (mm) | node EPE after stage 2 (mm) | "
             "masked test PSNR (dB) |",
             "|---|---|---:|---:|---:|---|---:|---:|"]
    for scene in s2scenes:
        for fl in FAILURES:
            ref = [q2(res[(scene, fl, sd, "no-carap", True)]) for sd in seeds]
            c1 = cell(res, scene, fl, seeds, "full", "no-carap", q1, True)
            c2 = cell(res, scene, fl, seeds, "full", "no-carap", q2, True)
            cn = cell(res, scene, fl, seeds, "full", "no-carap", lambda m: m["epe"], True)
            ps = [res[(scene, fl, sd, "full", True)]["test_psnr_masked"] - res[(scene, fl, sd, "no-carap", True)]
                  ["test_psnr_masked"] for sd in seeds]
            per_seed = ", ".join(f"{x:+.1f}" for x in c2[4])
            rows2.append(f"| {scene} | {fl} | {fmt(*mean_ci(ref), 4)} | {c1[0]} | {c2[0]} | {per_seed} | {cn[0]} | "
                         f"{fmt(*mean_ci(ps), 2)} |")

    # 3. Where the node-EPE difference lives (stage 1, full − no-carap, contributions in mm).
    hdr = [lab for _, lab in SPLITS]
    rows3 = ["| scene | failures | node EPE Δ (mm) | " + " | ".join(f"Δ by {h}" for h in hdr) +
             " | Δ node EPE weighted by query skinning (mm) | query EPE Δ (mm) | query EPE Δ by arm \\| box \\| "
             "ball (mm) | query EPE Δ, visible \\| hidden samples (mm) |",
             "|---|---|---:|" + "---|" * len(hdr) + "---:|---:|---|---|"]
    for scene in SCENES:
        for fl in FAILURES:
            dif = {}
            for sd in seeds:
                ca = split_contributions(res[(scene, fl, sd, "full", False)])
                cb = split_contributions(res[(scene, fl, sd, "no-carap", False)])
                for k in ca:
                    dif.setdefault(k, []).append(ca[k] - cb[k])
            node = cell(res, scene, fl, seeds, "full", "no-carap", node1)[0]
            parts = [" \\| ".join(f"{sum(dif[g]) / n:+.2f}" for g in groups) for groups, _ in SPLITS]
            qd = cell(res, scene, fl, seeds, "full", "no-carap", q1)[0]

            def qpart(path):
                def get(m):
                    v = m["epe_query"]["stage1"]
                    for p in path:
                        v = v.get(p, {})
                    return v.get("epe")
                xs = [get(res[(scene, fl, sd, "full", False)]) for sd in seeds]
                ys = [get(res[(scene, fl, sd, "no-carap", False)]) for sd in seeds]
                d = [1e3 * (x - y) for x, y in zip(xs, ys) if x is not None and y is not None]
                return f"{sum(d) / len(d):+.2f}" if d else "—"
            by_class = " \\| ".join(qpart(("by_class", c)) for c in ("arm", "box", "ball"))
            vis = " \\| ".join(qpart((k,)) for k in ("visible", "hidden"))
            rows3.append(f"| {scene} | {fl} | {node} | " + " | ".join(parts) +
                         f" | {fmt(*mean_ci(dif['weighted']), 2)} | {qd} | {by_class} | {vis} |")

    # 4. The run-time signals (no truth) beside C-ARAP − ARAP on the design and held-out seeds.
    rows4 = ["| scene | failures | low-confidence share | visibility flips | observed share | C-ARAP − ARAP, query "
             "EPE (mm), seeds " + " ".join(seeds) + " | C-ARAP − ARAP (mm), held-out seeds " + " ".join(hold) + " |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for scene in SCENES:
        for fl in FAILURES:
            def mean_signal(k):
                xs = [signal(res[(scene, fl, sd, "full", False)], k) for sd in seeds]
                xs = [x for x in xs if not math.isnan(x)]
                return mean_ci(xs)[0] if xs else float("nan")
            sig = {k: mean_signal(k) for k in ("low_confidence", "visibility_flips", "observed")}
            design = cell(res, scene, fl, seeds, "full", "no-carap", q1)
            held = cell(res, scene, fl, hold, "full", "no-carap", q1)
            rows4.append(f"| {scene} | {fl} | {sig['low_confidence']:.3f} | {sig['visibility_flips']:.3f} | "
                         f"{sig['observed']:.3f} | {design[0]} | {held[0]} |")

    m0 = res[(SCENES[0], FAILURES[0], seeds[0], "full", False)]
    secs1 = sum(r["seconds_total"] for k, r in res.items() if not k[4]) / max(1, sum(1 for k in res if not k[4]))
    secs2 = [r["seconds_total"] for k, r in res.items() if k[4]]
    cmd = (f"scripts/failure_study.py --seeds \"{' '.join(seeds)}\" --holdout-seeds \"{' '.join(hold)}\" "
           f"--stage2-scenes \"{' '.join(s2scenes)}\"")
    text = (f"<!-- ladder:failure-study -->\nGenerated by `{cmd}` on {datetime.date.today().isoformat()} "
            f"({platform.machine()}, {os.cpu_count()} cores, {a.jobs} runs at a time beside other work), {len(res)} runs: T = {m0['T']}, "
            f"{m0['width']}x{m0['height']}, {m0['stage1_iterations']} stage-1 iterations ({secs1:.1f} s a run)"
            + (f", {len(secs2)} full-pipeline runs ({sum(secs2) / len(secs2):.0f} s a run)" if secs2 else "") +
            ". **Query EPE** is the 3D end-point error of the "
            f"{m0['epe_query']['queries']} surface query tracks that `--export-dycheck` writes (the metric Dycheck "
            "and Shape-of-Motion report), carried by the run's nodes exactly as the `--data` path carries them "
            "(metrics.json `epe_query`); **node EPE** is the error of the node trajectories (a diagnostic). "
            "Differences are paired per seed (every seed is a different scene), mean ± 95 % interval, "
            "negative = C-ARAP better, with the seeds on which C-ARAP is better. With LRM: full − no-carap; "
            "without: no-lrm − smg-only.\n\n"
            "**Stage 1, every cell**:\n\n" + "\n".join(rows) + "\n\n"
            "**The full pipeline** (default stage 2, same seeds; the query EPE after stage 1 is of these runs' "
            "stage 1, the masked test PSNR of the two test views after stage 2):\n\n" + "\n".join(rows2) + "\n\n"
            "**Where the node-EPE difference lives** (stage 1, full − no-carap): each group's contribution to "
            "the node-EPE difference (mean over the seeds; the groups of a column sum to the total), and the "
            "node EPE weighted by each node's skinning weight on the query points:\n\n" + "\n".join(rows3) + "\n\n"
            "**What the trainer sees before stage 1** (metrics.json `signals`, no truth; means over the design "
            "seeds, full variant) beside C-ARAP − ARAP (with LRM) on the design and the held-out seeds:\n\n" +
            "\n".join(rows4) + "\n<!-- /ladder:failure-study -->\n")
    write_section(a.doc, "failure-study", text)
    print(text)


if __name__ == "__main__":
    main()
