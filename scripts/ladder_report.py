#!/usr/bin/env python3
"""Tables of an ablation ladder run by scripts/ladder.sh (docs/results.md).

Reads OUT/<variant>_s<seed>/metrics.json for every variant and seed and writes, between the
markers <!-- ladder:SECTION --> and <!-- /ladder:SECTION --> of the results page (appended at the
end when missing; the rest of the page is kept):
  * means with 95 % confidence intervals over the seeds (Student's t, n - 1 degrees of freedom);
  * paired differences per seed for the comparisons the paper's order makes (A - B on the same
    seed, so the scene's own difficulty cancels), with their 95 % intervals and on how many seeds A
    is better, and a verdict per metric: better / tie (the interval holds 0) / worse;
  * the per-seed values.
Standard library only (the machines have no SciPy)."""
import argparse
import datetime
import json
import math
import os
import platform
import sys

# Two-sided 95 % quantiles of Student's t, by degrees of freedom.
T975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262,
        10: 2.228, 11: 2.201, 12: 2.179, 13: 2.160, 14: 2.145, 15: 2.131, 16: 2.120, 17: 2.110,
        18: 2.101, 19: 2.093, 20: 2.086, 25: 2.060, 30: 2.042}

# (key, column title, decimals, +1 if higher is better, -1 if lower is better)
# The query EPE (the surface query tracks users report, metrics.json epe_query after stage 2) comes
# first among the 3D errors; node EPE ("epe") is the diagnostic (docs/results.md).
METRICS = [("test_psnr_masked", "masked PSNR (dB)", 2, +1),
           ("test_ssim", "SSIM", 4, +1),
           ("test_ssim_masked", "masked SSIM", 4, +1),
           ("query_epe", "query EPE (m)", 4, -1),
           ("query_epe_hidden", "query EPE hidden (m)", 4, -1),
           ("epe", "node EPE (m)", 4, -1),
           ("epe_hidden", "node EPE unobserved (m)", 4, -1),
           ("delta_10", "node δ10", 3, +1)]


def flatten_queries(m):
    """Adds query_epe / query_epe_hidden (after stage 2) to a run's metrics where it has epe_query."""
    q = m.get("epe_query")
    if q:
        m["query_epe"] = q["stage2"]["all"]["epe"]
        m["query_epe_hidden"] = q["stage2"].get("hidden", {}).get("epe")
    return m
# Comparisons of the paper's order (full >= no-lrm >= no-carap ~ smg-only > base; full > mosca),
# each as (A, B, what A - B isolates).
PAIRS = [("full", "no-lrm", "LRM on top of C-ARAP"),
         ("no-lrm", "smg-only", "C-ARAP against ARAP, no LRM"),
         ("full", "no-carap", "C-ARAP against ARAP, with LRM"),
         ("no-lrm", "no-carap", "C-ARAP alone against LRM alone"),
         ("no-carap", "smg-only", "LRM on top of ARAP"),
         ("smg-only", "mosca", "semantic gate (both plain ARAP)"),
         ("smg-only", "base", "graph regulariser at all"),
         ("full", "mosca", "SMG against MoSca's graph")]


def t975(df):
    if df in T975:
        return T975[df]
    below = [d for d in T975 if d < df]
    return T975[max(below)] if df < 30 else 1.96


def mean_ci(xs):
    n = len(xs)
    mu = sum(xs) / n
    if n < 2:
        return mu, float("nan")
    sd = math.sqrt(sum((x - mu) ** 2 for x in xs) / (n - 1))
    return mu, t975(n - 1) * sd / math.sqrt(n)


def fmt(mu, half, nd):
    return f"{mu:.{nd}f}" if math.isnan(half) else f"{mu:.{nd}f} ± {half:.{nd}f}"


# The canary: a short run whose figures stand for the trainer's behaviour. The studies keep their
# runs in OUT across sessions and pair a cached baseline with new runs of a candidate, which is only
# sound when both came from a trainer that computes the same thing; a binary's hash cannot tell
# (rebuilding in another folder changes it, not the results), its figures can (every run is
# bitwise reproducible at --threads 1).
CANARY_ARGS = ["--scene", "standard", "--tracker-failures", "typical", "--seed", "0", "--threads", "1",
               "--stage2-iters", "20", "--no-pictures", "--no-view", "--no-image-eval", "--no-ply", "--quiet"]


def canary_figures(m, prefix=""):
    """The numeric leaves of a metrics.json as {"a.b": value}, without timings and paths."""
    out = {}
    for k, v in m.items():
        key = prefix + k
        if k.startswith("seconds") or k in ("out", "threads"):
            continue
        if isinstance(v, dict):
            out.update(canary_figures(v, key + "."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[key] = v
    return out


def canary_diff(old, new):
    """The first key (sorted) whose figure differs or exists in one only, with both values; None
    when the two are the same."""
    for k in sorted(set(old) | set(new)):
        if old.get(k) != new.get(k):
            return f"{k}: {old.get(k)} then, {new.get(k)} now"
    return None


def check_cache(trainer, out, run=None, flags=()):
    """Runs the canary with `trainer` and compares its figures with those OUT/canary.json recorded
    when OUT's first runs were made; exits naming the first difference (OUT's runs came from a
    trainer that computes something else). Without OUT/canary.json, records it (the runs already in
    OUT are taken to be this trainer's). Returns "recorded" or "same". `run(cmd)` runs a command
    (tests pass their own). `flags` go to the canary run too: a study whose runs pass every setting
    it depends on (scripts/defaults_study.py) pins them, so that its cache outlives a change of the
    trainer's defaults; without them the canary runs at the defaults, and a changed default refuses
    the cache, as it must for runs made at the defaults."""
    import shutil
    import subprocess
    run = run or (lambda cmd: subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL))
    os.makedirs(out, exist_ok=True)
    tmp = os.path.join(out, f".canary_run_{os.getpid()}")  # two studies may share OUT
    shutil.rmtree(tmp, ignore_errors=True)
    run([trainer] + CANARY_ARGS + list(flags) + ["--out", tmp])
    now = canary_figures(json.load(open(os.path.join(tmp, "metrics.json"))))
    shutil.rmtree(tmp, ignore_errors=True)
    path = os.path.join(out, "canary.json")
    if not os.path.exists(path):
        with open(path, "w") as f:
            json.dump(now, f, indent=1, sort_keys=True)
        return "recorded"
    diff = canary_diff(json.load(open(path)), now)
    if diff:
        # Named by the folder, not the program: scripts/ladder.sh calls this through python3 -c.
        sys.exit(f"canary: {out} holds runs of a trainer that computes something else: the canary run "
                 f"differs ({diff}); delete {out} or pass another --out")
    return "same"


def study_arguments(default_out, extra=None, canary_flags=(), before_check=None):
    """The command line the studies share (scripts/carap_study.py, scripts/failure_study.py,
    scripts/defaults_study.py): parses it and returns it, with --trainer resolved: without it the
    trainer is first built into build/release (scripts/build_trainer.sh, as scripts/ladder.sh does)
    and that binary is used. `extra(parser)`, when given, adds a study's own arguments. Then the
    canary (check_cache): OUT's cached runs are reused only when the trainer still computes what
    made them (`canary_flags`: the settings the study pins, as check_cache's `flags`);
    `before_check(args)`, when given, runs just before it (a study with a committed record of runs
    seeds OUT/canary.json from it)."""
    import subprocess
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="0 1 2 3 4")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", default=default_out)
    ap.add_argument("--doc", default="docs/results.md")
    ap.add_argument("--trainer", default=None,
                    help="the smg_trainer to run (default: build it into build/release first)")
    if extra:
        extra(ap)
    a = ap.parse_args()
    if a.trainer is None:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        subprocess.run([os.path.join(root, "scripts", "build_trainer.sh")], check=True)
        a.trainer = os.path.join(root, os.environ.get("SMG_BUILD_DIR") or "build/release",
                                 "examples", "smg_trainer")
    if before_check:
        before_check(a)
    check_cache(a.trainer, a.out, flags=canary_flags)
    return a


def write_section(doc, section, text):
    """Replaces the lines from <!-- ladder:SECTION --> to <!-- /ladder:SECTION --> of `doc` by
    `text` (which carries both markers), or appends `text` when the markers are missing."""
    begin, end = f"<!-- ladder:{section} -->", f"<!-- /ladder:{section} -->"
    old = open(doc).read() if os.path.exists(doc) else "# Results\n"
    if begin in old and end in old:
        new = old[:old.index(begin)] + text + old[old.index(end) + len(end) + 1:]
    else:
        new = old.rstrip("\n") + "\n\n" + text
    open(doc, "w").write(new)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--doc", required=True)
    ap.add_argument("--section", required=True)
    ap.add_argument("--seeds", required=True)
    ap.add_argument("--variants", required=True)
    ap.add_argument("--flags", default="")
    ap.add_argument("--jobs", default="1")
    a = ap.parse_args()
    seeds, variants = a.seeds.split(), a.variants.split()
    runs = {}
    for v in variants:
        runs[v] = []
        for s in seeds:
            path = os.path.join(a.out, f"{v}_s{s}", "metrics.json")
            if not os.path.exists(path):
                sys.exit(f"ladder_report.py: {path}: missing (run scripts/ladder.sh without --report-only)")
            runs[v].append(flatten_queries(json.load(open(path))))
    metrics = [m for m in METRICS if all(r.get(m[0]) is not None for v in variants for r in runs[v])]
    n = len(seeds)

    head = "| variant | " + " | ".join(m[1] for m in metrics) + " | time (s) |\n|---|" + "---:|" * (len(metrics) + 1)
    rows = []
    for v in variants:
        cells = [fmt(*mean_ci([r[k] for r in runs[v]]), nd) for k, _, nd, _ in metrics]
        cells.append(f"{sum(r['seconds_total'] for r in runs[v]) / n:.0f}")
        rows.append(f"| {v} | " + " | ".join(cells) + " |")

    dhead = ("| A − B | isolates | " + " | ".join(m[1] for m in metrics) + " |\n|---|---|" +
             "---:|" * len(metrics))
    drows, verdicts = [], []
    for A, B, what in PAIRS:
        if A not in runs or B not in runs:
            continue
        cells, vcells = [], []
        for k, _, nd, sign in metrics:
            d = [ra[k] - rb[k] for ra, rb in zip(runs[A], runs[B])]
            mu, half = mean_ci(d)
            wins = sum(1 for x in d if sign * x > 0)
            cells.append(f"{fmt(mu, half, nd)} ({wins}/{n})")
            if math.isnan(half) or abs(mu) <= half:
                vcells.append("tie")
            else:
                vcells.append("**better**" if sign * mu > 0 else "*worse*")
        drows.append(f"| {A} − {B} | {what} | " + " | ".join(cells) + " |")
        verdicts.append(f"| {A} vs {B} | " + " | ".join(vcells) + " |")
    vhead = "| A vs B | " + " | ".join(m[1] for m in metrics) + " |\n|---|" + "---|" * len(metrics)

    per_seed = ["| variant | " + " | ".join(f"seed {s}" for s in seeds) + " |", "|---|" + "---|" * n]
    for v in variants:
        per_seed.append(f"| {v} | " + " | ".join(f"{r['test_psnr_masked']:.2f} / {r['epe']:.4f} / {r['epe_hidden']:.4f}"
                                                 for r in runs[v]) + " |")
    m0 = runs[variants[-1]][0]
    cmd = (f"scripts/ladder.sh --seeds \"{' '.join(seeds)}\" --jobs {a.jobs} --section {a.section}" +
           (f" -- {a.flags}" if a.flags else ""))
    text = f"""<!-- ladder:{a.section} -->
Generated by `{cmd}` on {datetime.date.today().isoformat()} ({platform.machine()}, {os.cpu_count()} cores;
every run with {m0['threads']} thread{'' if m0['threads'] == 1 else 's'}, T = {m0['T']}, {m0['width']}x{m0['height']}, {m0['stage1_iterations']} stage-1 and
{m0['stage2_iterations']} stage-2 iterations, seeds {", ".join(seeds)}; every seed is a different scene).

Means with 95 % confidence intervals over the seeds (t distribution, {n - 1} degrees of freedom);
times are wall clock with {a.jobs} run{'' if a.jobs == '1' else 's'} at a time:

{head}
""" + "\n".join(rows) + f"""

Paired differences A − B over the same seeds, mean ± 95 % interval, and (in brackets) on how many
seeds A is better (higher PSNR, SSIM and δ10; lower EPE):

{dhead}
""" + "\n".join(drows) + f"""

Verdict per metric: **better** or *worse* when the interval of A − B excludes 0, tie otherwise:

{vhead}
""" + "\n".join(verdicts) + """

Per seed (masked PSNR dB / node EPE m / node EPE on unobserved samples m):

""" + "\n".join(per_seed) + f"\n<!-- /ladder:{a.section} -->\n"

    write_section(a.doc, a.section, text)
    print(text)


if __name__ == "__main__":
    main()
