#!/usr/bin/env python3
"""scripts/defaults_study.py's rule on hand-made runs: a candidate becomes the default only when it
is never worse beyond noise (query EPE or masked PSNR) in any cell and better (query EPE) in one.
And the studies' canary (scripts/ladder_report.py check_cache) with a stand-in trainer: recorded on
first use, accepted while the figures stay the same, refused naming the key when one changes. And the
whole study with a stand-in trainer: the held-out seeds run only the baseline and the value the design
seeds chose; every run goes into the record, which a later study with an empty OUT reads instead of
running again, and which a trainer computing something else may not extend."""
import json
import os
import shutil
import sys
import tempfile

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

# The canary: timings, paths and threads are not figures; nested figures are.
import ladder_report as lr  # noqa: E402
m = {"seconds_total": 9.5, "out": "x", "threads": 1, "test_psnr": None, "quiet": True,
     "epe_query": {"stage2": {"all": {"epe": 0.0665, "samples": 8192}}}, "nodes": 400}
assert lr.canary_figures(m) == {"epe_query.stage2.all.epe": 0.0665, "epe_query.stage2.all.samples": 8192,
                                "nodes": 400}, lr.canary_figures(m)
assert lr.canary_diff({"a": 1.0}, {"a": 1.0}) is None
assert lr.canary_diff({"a": 1.0, "b": 2}, {"a": 1.0, "b": 3}) == "b: 2 then, 3 now"
assert lr.canary_diff({"a": 1.0}, {}) == "a: 1.0 then, None now"
figures = {"value": 0.0665}


def fake_trainer(cmd):
    """Stands in for smg_trainer: writes metrics.json into --out with the current figures."""
    assert cmd[1:1 + len(lr.CANARY_ARGS)] == lr.CANARY_ARGS, cmd
    d = cmd[cmd.index("--out") + 1]
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "metrics.json"), "w") as f:
        json.dump({"epe_query": {"stage2": {"all": {"epe": figures["value"]}}}, "seconds_total": 1.0}, f)


with tempfile.TemporaryDirectory() as out:
    assert lr.check_cache("smg_trainer", out, fake_trainer) == "recorded"
    assert os.path.exists(os.path.join(out, "canary.json"))
    assert [f for f in os.listdir(out) if f.startswith(".canary_run")] == [], "the canary run folder is removed"
    assert lr.check_cache("smg_trainer", out, fake_trainer) == "same"
    seen = []
    assert lr.check_cache("smg_trainer", out, lambda cmd: (seen.append(cmd), fake_trainer(cmd)),
                          flags=["--w-accel", "0"]) == "same"
    assert seen[0][1 + len(lr.CANARY_ARGS):][:3] == ["--w-accel", "0", "--out"], seen
    figures["value"] = 0.0666
    try:
        lr.check_cache("smg_trainer", out, fake_trainer)
        raise AssertionError("a changed canary must be refused")
    except SystemExit as e:
        msg = str(e)
        assert "canary run differs (epe_query.stage2.all.epe: 0.0665 then, 0.0666 now)" in msg, msg
        assert f"delete {out} or pass another --out" in msg, msg
    # Refused, nothing overwritten: the record is still the first trainer's.
    assert json.load(open(os.path.join(out, "canary.json"))) == {"epe_query.stage2.all.epe": 0.0665}

# The whole study (main) with a stand-in trainer whose figures depend on its flags: --w-accel 0.1
# lowers the query EPE by 3 mm, 0.3 by 1 mm, --stage2-unobserved hold raises it by 1 mm. It refuses
# a run (the canary's included) that leaves a candidate's flag to the trainer's defaults: the study
# pins every candidate, so that its cache outlives a default it changed.
STAND_IN = """#!/usr/bin/env python3
import json, os, sys
a = sys.argv[1:]
flag = lambda k: a[a.index(k) + 1] if k in a else None
for k in ("--w-accel", "--stage2-unobserved", "--alpha"):
    if a.count(k) != 1:
        sys.exit(f"stand-in: {k} given {a.count(k)} times, not once: {a}")
seed = int(flag("--seed"))
with open(os.environ["STAND_IN_LOG"], "a") as log:
    log.write(" ".join(a) + "\\n")
epe = 0.05 + 1e-4 * (seed % 3) - {"0": 0, "0.1": 0.003, "0.3": 0.001}[flag("--w-accel")]
epe += 0.001 if flag("--stage2-unobserved") == "hold" else 0.0
epe -= 0.0005 if flag("--alpha") == "1" and seed % 2 == 1 else 0.0
epe += float(os.environ.get("STAND_IN_SHIFT", "0"))
m = {"test_psnr_masked": 25.0 + 0.01 * seed, "stage2_iterations": 7,
     "signals": {"low_confidence": 0.1, "visibility_flips": 0.01, "observed": 0.9}}
m["epe_query"] = {"stage2": {"all": {"epe": epe}, "visible": {"epe": epe}}}
os.makedirs(flag("--out"), exist_ok=True)
json.dump(m, open(os.path.join(flag("--out"), "metrics.json"), "w"))
"""


def study(tmp, out, record, candidates, phase="both", expect_exit=None):
    """Runs main() with the stand-in; returns the trainer calls it made (not the canary's)."""
    log = os.path.join(tmp, "calls.log")
    open(log, "w").close()
    os.environ["STAND_IN_LOG"] = log
    argv = sys.argv
    sys.argv = ["defaults_study.py", "--candidates", candidates, "--scenes", "standard occluder",
                "--failures", "off", "--seeds", "0 1 2", "--holdout-seeds", "5 6 7", "--phase", phase,
                "--jobs", "2", "--trainer", os.path.join(tmp, "stand_in_trainer"), "--out", out,
                "--doc", os.path.join(tmp, "results.md"), "--record", record]
    try:
        ds.main()
        assert expect_exit is None, "main() should have refused: " + expect_exit
    except SystemExit as e:
        assert expect_exit is not None and expect_exit in str(e), e
    finally:
        sys.argv = argv
    return [c for c in open(log).read().splitlines() if "--stage2-iters 20" not in c]


with tempfile.TemporaryDirectory() as tmp:
    trainer = os.path.join(tmp, "stand_in_trainer")
    with open(trainer, "w") as f:
        f.write(STAND_IN.replace("#!/usr/bin/env python3", "#!" + sys.executable))
    os.chmod(trainer, 0o755)
    out, doc, record = os.path.join(tmp, "out"), os.path.join(tmp, "results.md"), os.path.join(tmp, "rec.json")
    calls = study(tmp, out, record, "w-accel stage2-unobserved")
    made = sorted(d for d in os.listdir(out) if not d.endswith(".json"))
    held = sorted(d for d in made if d.endswith(("_s5", "_s6", "_s7")))
    # Design seeds: the baseline and every value (4 tags x 2 cells x 3 seeds); held-out seeds: the
    # baseline and 0.1 only (0.3 lost on the design seeds, hold raised the EPE: none chosen).
    assert len(made) == 4 * 2 * 3 + 2 * 2 * 3 == len(calls), (made, calls)
    assert held == sorted(f"{sc}_off_{t}_s{sd}" for sc in ("standard", "occluder") for t in ("default", "w-accel_0.1")
                          for sd in (5, 6, 7)), held
    text = open(doc).read()
    # One section per candidate, so that a later study of another candidate leaves these alone.
    assert text.count("<!-- ladder:defaults-study-w-accel -->") == 1, text
    assert text.count("<!-- /ladder:defaults-study-stage2-unobserved -->") == 1, text
    assert "Chosen on the design seeds: 0.1." in text and "Held-out seeds 5 6 7: `--w-accel 0.1`" in text, text
    assert "Chosen on the design seeds: none (no value lowers the query EPE); the default stays move." in text, text
    assert "Verdict: **becomes the default**" in text, text
    assert "`--stage2-unobserved move --w-accel 0 --alpha 0.6`" in text, text
    assert ds.pinned("w-accel", "0.1") == ["--stage2-unobserved", "move", "--w-accel", "0.1", "--alpha", "0.6"]
    # The record holds every run (what the tables read) and the canary; a fresh OUT runs nothing.
    rec = json.load(open(record))
    assert sorted(rec["runs"]) == made and rec["canary"] == json.load(open(os.path.join(out, "canary.json"))), rec
    assert rec["runs"]["standard_off_default_s0"]["epe_query"]["stage2"]["all"]["epe"] == 0.05, rec
    shutil.rmtree(out)
    before = open(doc).read()
    assert study(tmp, out, record, "w-accel stage2-unobserved") == [], "the record's runs are not repeated"
    assert open(doc).read() == before, "the same runs write the same tables"

    # --alpha: 1 lowers the EPE by 0.5 mm on odd seeds, so it is chosen on the design seeds and the
    # held-out seeds run the baseline (recorded already) and 1: its 2 cells x 6 seeds, nothing else.
    calls = study(tmp, out, record, "alpha")
    assert len(calls) == 2 * 6 and all(c.endswith("--alpha 1") for c in calls), calls
    text = open(doc).read()
    assert text.count("<!-- ladder:defaults-study-alpha -->") == 1 and "Chosen on the design seeds: 1." in text
    assert "Held-out seeds 5 6 7: `--alpha 1`" in text, text
    assert "Chosen on the design seeds: 0.1." in text, "the other candidates' sections are left as they were"
    # A trainer that computes something else may not extend the record (a fresh OUT takes the
    # record's canary), and the record is left as it was.
    rec = open(record).read()
    os.environ["STAND_IN_SHIFT"] = "1e-6"
    study(tmp, os.path.join(tmp, "out3"), record, "w-accel", expect_exit="computes something else")
    del os.environ["STAND_IN_SHIFT"]
    assert open(record).read() == rec
    # A file that is not such a record is refused, naming it, and left as it was.
    for bad in ("not json", '{"runs": []}', '{"canary": null, "runs": {"x": {"epe_query": 3}}}'):
        other = os.path.join(tmp, "other.json")
        open(other, "w").write(bad)
        study(tmp, os.path.join(tmp, "out4"), other, "w-accel", expect_exit=f"--record {other}: not a record")
        assert open(other).read() == bad
print("defaults_study rule: ok")
