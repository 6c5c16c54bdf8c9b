#!/usr/bin/env python3
"""What smg_trainer turns on by default, chosen by one protocol (docs/results.md, "Defaults by
evidence"; issue 47).

Every candidate is a trainer flag with a baseline value (the trainer's default when the study began)
and one or more other values:
  stage2-unobserved  move (baseline) | hold: stage 2 leaves a node's unobserved frames to the regularisers
  w-accel            0 (baseline) | 0.1 | 0.3: trajectory smoothness (E21)
  alpha              0.6 (baseline, C-ARAP) | 1 (plain ARAP, and LRM without confidences)
Every run passes every candidate's flag: the baseline run all baseline values, a candidate's run
the baseline values with its own value in place. So each candidate is judged against the same
baseline, alone, and the runs (and the canary) do not depend on the trainer's defaults: the cache
and the verdicts outlive a default the study changed. The chosen values together are what the
ladder (scripts/ladder.sh) runs once they ship.
Each value runs the full pipeline (stages 0-2, --threads 1) on every cell (scene x tracker-failure
level) and seed, beside the baseline on the same cell and seed, and is scored by what users measure:
the 3D EPE of the surface query tracks after stage 2 (all samples, truly visible and hidden ones)
and the masked test PSNR. The protocol:
  1. design seeds (--seeds): per candidate, the value with the lowest mean paired query-EPE change
     over every cell is chosen (none when no value lowers it);
  2. held-out seeds (--holdout-seeds), never used in step 1: the chosen value becomes the default
     only where, in every cell, it is never worse beyond noise (the paired 95 % interval of the
     query-EPE change lies above 0, or that of the masked-PSNR change below 0) and it is better
     somewhere (an interval of the query-EPE change below 0).
It writes each candidate's tables and verdict between <!-- ladder:defaults-study-CANDIDATE --> and
<!-- /ladder:defaults-study-CANDIDATE --> of the results page, so candidates can be studied apart.
Every run's figures (what the tables read of its metrics.json) go at once into the record
(--record, docs/data/defaults_study.json, committed), with the canary of the trainer that made
them: a run found in OUT or in the record is not repeated, so a study runs in parts (--phase design
first), across sessions and clones, and anyone can rewrite the tables from the record. A short
canary run first checks that the trainer still computes what made them (ladder_report.check_cache);
a record made by another trainer is refused, naming the figure.
alpha had a third value until 2026-11-29, auto (a rule in the trainer that picked C-ARAP or plain
ARAP from signals seen before stage 1): the design seeds chose it, the held-out seeds rejected it,
and it was removed from the trainer and from here (docs/results.md, "What the trainer sees before
stage 1"). Its runs stay in the record (folder names *_alpha_auto_*), unread by this version.
Usage: scripts/defaults_study.py [--candidates "stage2-unobserved w-accel alpha"]
                                 [--scenes "standard occluder bending"] [--failures "off typical double"]
                                 [--seeds "0 1 2 3 4"] [--holdout-seeds "5 6 7 8 9"] [--phase design|both]
                                 [--jobs 2] [--out build/defaults_study] [--doc docs/results.md]
                                 [--trainer build/release/examples/smg_trainer]
                                 [--record docs/data/defaults_study.json | --record ""]
Without --trainer it first builds the trainer into build/release (scripts/build_trainer.sh)."""
import concurrent.futures
import datetime
import json
import os
import platform
import subprocess
import sys
import threading

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ladder_report import canary_diff, fmt, mean_ci, study_arguments, write_section  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SCENES = ["standard", "occluder", "bending"]
FAILURES = ["off", "typical", "double"]
# candidate (a trainer flag) -> (baseline value, [other values]). The baseline values were the
# trainer's defaults when the study began; they are passed explicitly, never left to the defaults.
CANDIDATES = {
    "stage2-unobserved": ("move", ["hold"]),
    "w-accel": ("0", ["0.1", "0.3"]),
    "alpha": ("0.6", ["1"]),
}
BASE = "default"  # the baseline run's tag (its folder names keep it: OUT/<scene>_<failures>_default_s<seed>)


def pinned(candidate=None, value=None):
    """The flags of a run: every candidate at its baseline value, `candidate` at `value`."""
    out = []
    for c, (base, _) in CANDIDATES.items():
        out += [f"--{c}", value if c == candidate else base]
    return out


def extra_arguments(ap):
    ap.add_argument("--candidates", default=" ".join(CANDIDATES))
    ap.add_argument("--scenes", default=" ".join(SCENES))
    ap.add_argument("--failures", default=" ".join(FAILURES))
    ap.add_argument("--holdout-seeds", default="5 6 7 8 9", help="the seeds the choice is confirmed on")
    ap.add_argument("--phase", choices=["design", "both"], default="both",
                    help="design: run and report the design seeds only")
    ap.add_argument("--record", default=os.path.join(ROOT, "docs", "data", "defaults_study.json"),
                    help="the committed record of every run's figures ('' for none)")


def summary(m):
    """What the study reads of a run's metrics.json, as the record keeps it: the query EPE after
    stage 2 by part, the masked PSNR, the stage-2 iterations, the time and the signals (and, in the
    runs of the removed --alpha auto, the rigidity term it picked)."""
    s2 = m["epe_query"]["stage2"]
    keep = {"epe_query": {"stage2": {p: {"epe": s2[p].get("epe")} for p in ("all", "visible", "hidden") if p in s2}},
            "test_psnr_masked": m.get("test_psnr_masked")}
    for k in ("stage2_iterations", "seconds_total", "signals", "rigidity"):
        if k in m:
            keep[k] = m[k]
    return keep


class Record:
    """The record (--record): {"canary": figures, "runs": {run folder name: summary}}. Runs are
    added as they finish and the file is rewritten whole each time (atomically), so a study cut
    short keeps every run it finished. path None: no record."""

    def __init__(self, path):
        self.path, self.lock = path, threading.Lock()
        self.data = {"canary": None, "runs": {}}
        if path and os.path.exists(path):
            try:
                self.data = json.load(open(path))
                assert isinstance(self.data.get("runs"), dict)
                self.data["runs"] = {k: summary(v) for k, v in self.data["runs"].items()}
            except (ValueError, AssertionError, KeyError, TypeError, AttributeError):
                sys.exit(f"defaults_study: --record {path}: not a record this script wrote (delete it or pass another)")

    def get(self, name):
        return self.data["runs"].get(name)

    def add(self, name, m):
        with self.lock:
            self.data["runs"][name] = summary(m)
            self.save()

    def save(self):
        if not self.path:
            return
        os.makedirs(os.path.dirname(os.path.abspath(self.path)), exist_ok=True)
        # One line per run (sorted), so that a commit's diff shows the runs it adds.
        runs = sorted(self.data["runs"].items())
        lines = ['{"canary": ' + json.dumps(self.data["canary"], sort_keys=True) + ",", ' "runs": {']
        lines += [f"  {json.dumps(k)}: {json.dumps(v, sort_keys=True)}" + ("," if i + 1 < len(runs) else "")
                  for i, (k, v) in enumerate(runs)]
        tmp = f"{self.path}.tmp{os.getpid()}"
        with open(tmp, "w") as f:
            f.write("\n".join(lines + [" }}"]) + "\n")
        os.replace(tmp, self.path)


def run(trainer, out, record, scene, failures, seed, tag, flags):
    """The figures of one full-pipeline run (tag names the flags): from OUT's metrics.json, else
    from the record, else run now and recorded."""
    name = f"{scene}_{failures}_{tag}_s{seed}"
    path = os.path.join(out, name, "metrics.json")
    if not os.path.exists(path):
        if record.get(name) is not None:
            return record.get(name)
        cmd = [trainer, "--scene", scene, "--tracker-failures", failures, "--seed", str(seed), "--threads", "1",
               "--no-pictures", "--no-view", "--quiet", "--out", os.path.join(out, name)] + flags
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    m = json.load(open(path))
    if record.get(name) is None:
        record.add(name, m)
    return m


def check_record(record, out):
    """The record's runs pair with OUT's only when one trainer made both: the record keeps the canary
    it was made with (OUT/canary.json, which check_cache has just compared with this trainer)."""
    now = json.load(open(os.path.join(out, "canary.json")))
    if record.data.get("canary") is None:
        record.data["canary"] = now
        return
    diff = canary_diff(record.data["canary"], now)
    if diff:
        sys.exit(f"defaults_study: --record {record.path} holds runs of a trainer that computes something "
                 f"else: the canary differs ({diff}); pass another --record, or --record '' to run without")


def query(m, part="all"):
    """Query EPE after stage 2 (m); None when the part has no samples."""
    return m["epe_query"]["stage2"].get(part, {}).get("epe")


# (name, title, metric, scale to the table's unit, decimals, +1 higher is better / -1 lower is better)
MEASURES = [("epe", "query EPE (mm)", lambda m: query(m), 1e3, 2, -1),
            ("visible", "visible (mm)", lambda m: query(m, "visible"), 1e3, 2, -1),
            ("hidden", "hidden (mm)", lambda m: query(m, "hidden"), 1e3, 2, -1),
            ("psnr", "masked PSNR (dB)", lambda m: m["test_psnr_masked"], 1.0, 2, +1)]


def paired(res, cells, seeds, a, b, metric, scale):
    """metric(a) − metric(b) per (cell, seed) in the table's unit; pairs with a missing part dropped."""
    out = []
    for c in cells:
        for sd in seeds:
            va, vb = metric(res[c + (sd, a)]), metric(res[c + (sd, b)])
            if va is not None and vb is not None:
                out.append(scale * (va - vb))
    return out


def verdict(dd, sense):
    """'better' / 'worse' when the 95 % interval of the change excludes 0 (sense: +1 higher is
    better), else 'tie'."""
    if len(dd) < 2:
        return "tie"
    mu, half = mean_ci(dd)
    if mu - half > 0:
        return "better" if sense > 0 else "worse"
    if mu + half < 0:
        return "worse" if sense > 0 else "better"
    return "tie"


def entry(dd, sense, nd, judged=True):
    """One table entry: mean ± 95 %, the pairs on which the candidate is better, the verdict."""
    if not dd:
        return "–", None
    mu, half = mean_ci(dd)
    wins = sum(1 for x in dd if x * sense > 0)
    v = verdict(dd, sense) if judged else "tie"
    return f"{fmt(mu, half, nd)} ({wins}/{len(dd)}){'' if v == 'tie' else ' ' + v}", v


def table(res, cells, seeds, a, b):
    """Per cell: each measure's paired change a − b (mean ± 95 %, seeds on which a is better) and
    its verdict, then every cell's pairs pooled (for reading only: the rule judges cell by cell);
    returns (rows, verdicts by cell and measure)."""
    rows = ["| scene | failures | " + " | ".join(f"Δ {t}" for _, t, *_ in MEASURES) + " |",
            "|---|---|" + "---:|" * len(MEASURES)]
    verdicts = {}
    for c in cells + [None]:
        parts = []
        for name, _, metric, scale, nd, sense in MEASURES:
            text, v = entry(paired(res, cells if c is None else [c], seeds, a, b, metric, scale), sense, nd,
                            judged=c is not None)
            parts.append(text)
            if c is not None and v is not None:
                verdicts[(c, name)] = v
        rows.append(("| all cells | pooled | " if c is None else f"| {c[0]} | {c[1]} | ") + " | ".join(parts) + " |")
    return rows, verdicts


def mean_change(res, cells, seeds, a, b):
    dd = paired(res, cells, seeds, a, b, MEASURES[0][2], 1e3)
    return sum(dd) / len(dd)


def adopts(verdicts):
    """Never worse beyond noise (query EPE or masked PSNR) in any cell, better (query EPE) in one."""
    worse = any(v == "worse" for (c, name), v in verdicts.items() if name in ("epe", "psnr"))
    better = any(v == "better" for (c, name), v in verdicts.items() if name == "epe")
    return better and not worse


def main():
    record = None

    def seed_canary(a):
        # A fresh OUT takes the record's canary, so that check_cache compares this trainer with the
        # one that made the record's runs.
        nonlocal record
        record = Record(a.record or None)
        canary = os.path.join(a.out, "canary.json")
        if record.data.get("canary") is not None and not os.path.exists(canary):
            os.makedirs(a.out, exist_ok=True)
            with open(canary, "w") as f:
                json.dump(record.data["canary"], f, indent=1, sort_keys=True)

    a = study_arguments("build/defaults_study", extra_arguments, canary_flags=pinned(), before_check=seed_canary)
    check_record(record, a.out)
    seeds, hold = a.seeds.split(), a.holdout_seeds.split()
    cands = a.candidates.split()
    for c in cands:
        if c not in CANDIDATES:
            sys.exit(f"defaults_study: --candidates: unknown candidate '{c}' (known: {' '.join(CANDIDATES)})")
    cells = [(s, f) for s in a.scenes.split() for f in a.failures.split()]
    flags = {BASE: pinned()}
    for c in cands:
        for value in CANDIDATES[c][1]:
            flags[f"{c}={value}"] = pinned(c, value)
    os.makedirs(a.out, exist_ok=True)
    with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
        def run_all(keys):
            futs = {k: ex.submit(run, a.trainer, a.out, record, k[0], k[1], k[2], k[3].replace("=", "_"),
                                 flags[k[3]]) for k in keys}
            return {k: f.result() for k, f in futs.items()}
        # Design seeds: every value of every candidate. The choice is made on them alone, and the
        # held-out seeds then run only the baseline and the chosen values, so a value the design
        # seeds rejected costs no held-out run.
        res = {}
        res.update(run_all([cell + (sd, tag) for cell in cells for sd in seeds for tag in flags]))
        chosen = {}
        for c in cands:
            tags = [f"{c}={value}" for value in CANDIDATES[c][1]]
            means = {t: mean_change(res, cells, seeds, t, BASE) for t in tags}
            best = min(tags, key=lambda t: means[t])
            chosen[c] = (tags, means, best if means[best] < 0 else None)
        if a.phase == "both":
            held_tags = [BASE]
            held_tags += [best for _, _, best in chosen.values() if best is not None]
            res.update(run_all([cell + (sd, tag) for cell in cells for sd in hold for tag in held_tags]))

    base_m = res[cells[0] + (seeds[0], BASE)]
    for c in cands:
        section = f"defaults-study-{c}"
        lines = [f"<!-- ladder:{section} -->",
                 f"Written by `scripts/defaults_study.py --candidates \"{c}\" --scenes \"{a.scenes}\" "
                 f"--failures \"{a.failures}\" --seeds \"{a.seeds}\" --holdout-seeds \"{a.holdout_seeds}\" "
                 f"--phase {a.phase}` on {datetime.date.today()} ({platform.machine()}, full pipeline, "
                 f"{base_m.get('stage2_iterations')} stage-2 iterations, one thread per run). Each entry is the "
                 "paired change candidate − baseline over the seeds of the cell (the baseline: the trainer's "
                 f"defaults when the study began, `{' '.join(pinned())}`, passed to every run with the "
                 "candidate's own value in place): mean ± 95 % interval (Student's t), the seeds on which the "
                 "candidate is better, and a verdict where the interval excludes 0. Query EPE: the surface "
                 "query tracks after stage 2 (all, truly visible, hidden samples).",
                 ""]
        base_label = CANDIDATES[c][0]
        lines += [f"**`--{c}`** (baseline: {base_label})", ""]
        tags, means, best = chosen[c]
        for t in tags:
            rows, _ = table(res, cells, seeds, t, BASE)
            lines += [f"Design seeds {a.seeds}: `--{c} {t.split('=')[1]}` − `{base_label}` "
                      f"(query EPE over all cells {means[t]:+.2f} mm)", ""] + rows + [""]
        if best is None:
            lines += [f"Chosen on the design seeds: none (no value lowers the query EPE); the default stays "
                      f"{base_label}.", ""]
        else:
            lines += [f"Chosen on the design seeds: {best.split('=')[1]}.", ""]
            if a.phase != "both":
                lines += ["Not yet confirmed on held-out seeds (--phase design).", ""]
            else:
                rows, verdicts = table(res, cells, hold, best, BASE)
                ok = adopts(verdicts)
                lines += [f"Held-out seeds {a.holdout_seeds}: `--{c} {best.split('=')[1]}` − `{base_label}`", ""]
                lines += rows + ["", f"Verdict: **{'becomes the default' if ok else 'not adopted'}** "
                                     f"({'never worse beyond noise and better somewhere' if ok else 'the rule is not met'}).",
                                 ""]
        lines.append(f"<!-- /ladder:{section} -->")
        write_section(a.doc, section, "\n".join(lines) + "\n")
        print("\n".join(lines))
    record.save()


if __name__ == "__main__":
    main()
