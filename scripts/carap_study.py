#!/usr/bin/env python3
"""The C-ARAP study of docs/results.md: what the confidences measure and what moves C-ARAP.

Runs smg_trainer's stage 0 and stage 1 only (--stage2-iters 0: the node trajectories, hence the
3D errors reported here, are stage 1's; stage 2 moves them by about 1 %) for each configuration
below on both generated scenes and every seed, then writes, between the markers
<!-- ladder:carap-study --> and <!-- /ladder:carap-study --> of the results page, per scene:
  * stage-1 node EPE and EPE on unobserved samples, mean ± 95 % interval, and the paired
    difference to plain ARAP (no-carap: the same graph and LRM) with the seeds on which it is
    better;
  * the confidence diagnostics of the full variant (nodes.hpp, confidence_diagnostics).
Usage: scripts/carap_study.py [--seeds "0 1 2 3 4"] [--jobs 2] [--out build/carap_study]
                              [--doc docs/results.md] [--trainer build/release/examples/smg_trainer]
Without --trainer it first builds the trainer into build/release (scripts/build_trainer.sh, as
scripts/ladder.sh does); with --trainer it runs that binary as it is.
A run whose metrics.json exists is not repeated (delete OUT to start over); a short canary run
first checks that the trainer still computes what made them (ladder_report.check_cache)."""
import concurrent.futures
import datetime
import json
import os
import platform
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ladder_report import fmt, mean_ci, study_arguments, write_section  # noqa: E402

# (name, variant, extra flags, what it tests)
CONFIGS = [
    ("arap", "no-carap", [], "plain ARAP (+ LRM): the reference of every difference"),
    ("full", "full", [], "C-ARAP as the paper defines it (α 0.6, symmetric, confidences from the estimate)"),
    ("alpha-0", "full", ["--alpha", "0"], "α = 0: w̃ = w c"),
    ("alpha-0.3", "full", ["--alpha", "0.3"], ""),
    ("alpha-0.9", "full", ["--alpha", "0.9"], ""),
    ("alpha-1", "full", ["--alpha", "1"], "α = 1: C-ARAP = ARAP, LRM unweighted"),
    ("lifted", "full", ["--confidence-from", "lifted"], "confidences once, from the lifted trajectories"),
    ("truth", "full", ["--confidence-from", "truth"], "confidences from the true trajectories (oracle)"),
    ("no-visibility", "full", ["--confidence-visibility", "off"],
     "confidences without E6's visibility factor (c = c^m c^r)"),
    ("truth-no-visibility", "full", ["--confidence-from", "truth", "--confidence-visibility", "off"],
     "oracle trajectories and no visibility factor: c < 1 only where true motion is not translation-like"),
    ("directed", "full", ["--carap-reading", "directed"], "reading B: term i-j moves node i only (E20)"),
    ("directed-alpha-1", "full", ["--carap-reading", "directed", "--alpha", "1"],
     "reading B without confidences: the directed update alone"),
    ("directed-w0.2", "full", ["--carap-reading", "directed", "--w-rigidity", "0.2"],
     "reading B at twice the rigidity weight (a node gets only its own terms' pull)"),
    ("directed-no-lrm", "no-lrm", ["--carap-reading", "directed"], "reading B without LRM"),
    ("no-lrm", "no-lrm", [], "C-ARAP without LRM"),
    ("smg-only", "smg-only", [], "plain ARAP without LRM"),
]
SCENES = ["standard", "occluder"]
DIAG = [("conf_spearman_error", "Spearman(c, error of the estimate)", 3),
        ("conf_spearman_observation", "Spearman(c, error of the observation)", 3),
        ("conf_obs_err_below_3cm", "mean c, observation error < 3 cm", 3),
        ("conf_obs_err_3_10cm", "mean c, 3–10 cm", 3),
        ("conf_obs_err_10_30cm", "mean c, 10–30 cm", 3),
        ("conf_obs_err_above_30cm", "mean c, > 30 cm", 3),
        ("conf_mean_observed", "mean c over observed samples", 3),
        ("conf_mean_observed_truth", "the same, c of the true trajectories", 3),
        ("conf_low_observed", "observed samples with c < 0.3", 3),
        ("conf_low_observed_truth", "the same, c of the true trajectories", 3),
        ("conf_low_fraction", "samples with c < 0.3 (all, observed or not)", 3),
        ("conf_weight_symmetric_low", "rigidity weight on a c < 0.3 sample / ARAP, symmetric reading", 3),
        ("conf_weight_symmetric_high", "the same on a c ≥ 0.7 sample", 3),
        ("conf_weight_directed_low", "rigidity weight on a c < 0.3 sample / ARAP, directed reading", 3),
        ("conf_weight_directed_high", "the same on a c ≥ 0.7 sample", 3)]


def run(trainer, out, scene, seed, name, variant, extra):
    d = os.path.join(out, f"{scene}_{name}_s{seed}")
    path = os.path.join(d, "metrics.json")
    if os.path.exists(path):
        return json.load(open(path))
    cmd = [trainer, "--scene", scene, "--seed", str(seed), "--variant", variant, "--stage2-iters", "0",
           "--threads", "1", "--no-pictures", "--no-view", "--quiet", "--out", d] + extra
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.load(open(path))


def main():
    a = study_arguments("build/carap_study")
    seeds = a.seeds.split()
    os.makedirs(a.out, exist_ok=True)
    jobs = [(s, sd, c) for s in SCENES for sd in seeds for c in CONFIGS]
    with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
        futs = {(s, sd, c[0]): ex.submit(run, a.trainer, a.out, s, sd, c[0], c[1], c[2]) for s, sd, c in jobs}
        res = {k: f.result() for k, f in futs.items()}
    n = len(seeds)
    parts = []
    for scene in SCENES:
        rows = ["| configuration | what it tests | node EPE (m) | vs ARAP | EPE unobserved (m) | vs ARAP | stage 1 (s) |",
                "|---|---|---:|---:|---:|---:|---:|"]
        for name, _, _, what in CONFIGS:
            cells = []
            for key in ("epe_stage1", "epe_hidden_stage1"):
                xs = [res[(scene, sd, name)][key] for sd in seeds]
                ref = [res[(scene, sd, "arap")][key] for sd in seeds]
                cells.append(fmt(*mean_ci(xs), 4))
                if name == "arap":
                    cells.append("")
                else:
                    dd = [x - r for x, r in zip(xs, ref)]
                    wins = sum(1 for x in dd if x < 0)
                    cells.append(f"{fmt(*mean_ci(dd), 4)} ({wins}/{n})")
            secs = sum(res[(scene, sd, name)]["seconds_stage1"] for sd in seeds) / n
            rows.append(f"| {name} | {what} | " + " | ".join(cells) + f" | {secs:.1f} |")
        diag = ["| diagnostic (full variant) | lifted trajectories | after stage 1 |", "|---|---:|---:|"]
        for key, title, nd in DIAG:
            lifted = fmt(*mean_ci([res[(scene, sd, "full")][key + "_lifted"] for sd in seeds]), nd)
            final = fmt(*mean_ci([res[(scene, sd, "full")][key] for sd in seeds]), nd)
            diag.append(f"| {title} | {lifted} | {final} |")
        parts.append(f"#### Scene `{scene}`\n\n" + "\n".join(rows) + "\n\n" + "\n".join(diag) + "\n")
    m0 = res[(SCENES[0], seeds[0], "full")]
    text = (f"<!-- ladder:carap-study -->\nGenerated by `scripts/carap_study.py --seeds \"{' '.join(seeds)}\"` on "
            f"{datetime.date.today().isoformat()} ({platform.machine()}, {os.cpu_count()} cores): stage 0 and "
            f"stage 1 only ({m0['stage1_iterations']} iterations, T = {m0['T']}, {m0['width']}x{m0['height']}), every "
            f"configuration on seeds {', '.join(seeds)} of both scenes. Node EPE and EPE on unobserved samples are "
            "stage 1's (3D error of the node trajectories; stage 2 changes them by about 1 %), mean ± 95 % "
            "interval; \"vs ARAP\" is the paired difference to `arap` (negative = better) and the seeds on which "
            "the configuration is better. The diagnostics are means ± 95 % intervals over the seeds of the "
            "full variant's run.\n\n" + "\n".join(parts) + "<!-- /ladder:carap-study -->\n")
    write_section(a.doc, "carap-study", text)
    print(text)


if __name__ == "__main__":
    main()
