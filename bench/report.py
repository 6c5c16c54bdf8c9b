#!/usr/bin/env python3
"""Turn Google Benchmark JSON results into docs/performance.md (speed against error).

usage: bench/report.py RESULTS_DIR > performance.md

RESULTS_DIR holds one <module>.json per bench/bench_<module>.cpp run, or <module>-<tag>.json for
a run at other parameters (scripts/bench.sh --tag), each with an optional <name>.load (the load
average before and after, written by scripts/bench.sh). Each module's section starts with
bench/notes/<module>.md (what is measured and how), then for every result file: a header
generated from the file (date, machine, smg's build, the run-time parameters, the load, the
noise protocol), a table of every row (wall time median and min over the repetitions, process
CPU time, other processes' load, every counter with its unit) and a summary generated from the
numbers. bench/results/torch.json (bench/torch/bench_torch.py) also gives the energy section
its PyTorch autograd baseline rows. Standard library only.

       bench/report.py --highlights RESULTS_DIR [RESULTS_MD]
       bench/report.py --highlights-all RESULTS_DIR [RESULTS_MD]   (the long form, every table)
       bench/report.py --readme README.md [RESULTS_DIR [RESULTS_MD]]

The README's result highlights: a few headline lines with links (the energy and splat CPU
runs, smg_torch's GPU energies row, the ablation ladder's query EPE), generated from the same
JSON (RESULTS_DIR, default bench/results, with gpu/torch_cuda_h100.json when present) and from
the ablation-ladder tables of RESULTS_MD (default docs/results.md). --highlights prints the
block; --highlights-all the long form (every module's line or table, the whole smg_torch table
and the ladder's tables); --readme rewrites the lines between "<!-- smg:highlights begin -->"
and "<!-- smg:highlights end -->" of README.md in place with the short form.
scripts/check_docs.py checks that the README's block equals what this generates
(scripts/bench.sh --publish and scripts/ladder.sh rewrite it).
"""
import json
import math
import os
import re
import sys

ORDER = ["core", "graph", "energy", "skin", "splat", "executor", "torch"]
# bench/notes/<name>.md printed after the modules' sections, with no result file of their own
# (derivations rather than measurements).
NOTES_ONLY = ["roofline"]
HERE = os.path.dirname(os.path.abspath(__file__))
LOAD_COUNTERS = ("others_cpus", "loadavg_1m")


# ---- formatting ---------------------------------------------------------------------------------
def fmt(value, integer=False):
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if integer:
        return f"{int(round(value))}"
    if value == 0:
        return "0"
    a = abs(value)
    if a >= 1e5 or a < 1e-3:
        return f"{value:.2e}"
    if a >= 100:
        return f"{value:.0f}"
    if a >= 10:
        return f"{value:.1f}"
    return f"{value:.3g}"


def fmt_time(value):
    """A time: fixed point, never scientific notation."""
    if isinstance(value, (int, float)) and math.isfinite(value) and abs(value) >= 100:
        return f"{value:.0f}"
    return fmt(value)


def unit_of(counter):
    """The unit of a counter, from its name (bench/README.md lists the naming rule)."""
    if counter.startswith("ns_per") or counter.endswith("_ns"):
        return "ns"
    if counter.endswith("_ms"):
        return "ms"
    if counter.endswith("_mb"):
        return "MB"
    if counter.endswith("_per_s") or counter.endswith("_rate"):
        return "1/s"
    if counter == "others_cpus":
        return "CPUs"
    return ""


def clean_name(name):
    for part in ("/process_time", "/real_time", "/manual_time"):
        name = name.replace(part, "")
    return re.sub(r"/repeats:\d+", "", name)


# ---- loading ------------------------------------------------------------------------------------
class Result:
    """One result file: context, rows (median aggregates or plain iterations), the min aggregates."""

    def __init__(self, path):
        with open(path) as f:
            data = json.load(f)
        self.path = path
        self.context = data.get("context", {})
        runs = data.get("benchmarks", [])
        # Per row: the median aggregate when it was repeated, otherwise its single iteration run.
        self.rows, seen = [], {}
        for b in runs:
            key = b.get("run_name", b["name"])
            if b.get("run_type", "iteration") == "aggregate" and b.get("aggregate_name") != "median":
                continue
            if key in seen:
                if b.get("aggregate_name") == "median":
                    self.rows[seen[key]] = b
                continue
            seen[key] = len(self.rows)
            self.rows.append(b)
        self.aggregated = any(b.get("aggregate_name") == "median" for b in self.rows)
        self.reps = {}
        for b in self.rows:
            r = b.get("repetitions", 1) if b.get("aggregate_name") == "median" else 1
            self.reps[r] = self.reps.get(r, 0) + 1
        self.mins = {b.get("run_name", b["name"]): b for b in runs if b.get("aggregate_name") == "min"}
        for b in self.rows:
            b["clean"] = clean_name(b.get("run_name", b["name"]))
        self.load = {}
        load_path = path[:-5] + ".load"
        if os.path.exists(load_path):
            with open(load_path) as f:
                for line in f:
                    parts = line.split(None, 1)
                    if len(parts) == 2:
                        self.load[parts[0]] = parts[1].strip()

    def min_of(self, row, key="real_time"):
        m = self.mins.get(row.get("run_name", row["name"]))
        return m.get(key) if m else None

    def find(self, pattern):
        """Rows whose clean name matches the regular expression."""
        return [b for b in self.rows if re.search(pattern, b["clean"])]

    def one(self, pattern):
        rows = self.find(pattern)
        return rows[0] if rows else None


RESERVED = {"name", "family_index", "per_family_instance_index", "run_name", "run_type",
            "repetitions", "repetition_index", "threads", "iterations", "real_time", "cpu_time",
            "time_unit", "aggregate_name", "aggregate_unit", "label", "error_occurred",
            "error_message", "items_per_second", "bytes_per_second", "clean"}


# ---- the generated header of one result file ---------------------------------------------------
def header(res, module, raw):
    c = res.context
    out = []
    cpus = c.get("num_cpus", "?")
    mhz = c.get("mhz_per_cpu", "?")
    date = c.get("date", "?")
    host = c.get("host_name")
    out.append(f"*Run:* {date}{' on ' + host if host else ''}, {cpus} CPUs at {mhz} MHz; "
               f"raw data `{raw}`.")
    if "smg_build_type" in c:
        out.append(f"*smg build:* {c['smg_build_type']}, {c.get('smg_compiler', '?')}, flags "
                   f"`{c.get('smg_cxx_flags', '?')}`. Google Benchmark's own `library_build_type` "
                   f"({c.get('library_build_type', '?')}) is how the installed benchmark library "
                   f"(the Debian package) was compiled, not smg; it does not change the measured "
                   f"code.")
        out.append(f"*Parameters:* `{c.get('smg_params', '?')}`.")
    elif module == "torch":
        out.append(f"*smg build:* {c.get('library_build_type', '?')} (as bench_torch.py records it).")
    else:
        out.append(f"*smg build:* not recorded (a run from before the build was recorded; "
                   f"Google Benchmark's library build type: {c.get('library_build_type', '?')}, "
                   f"which is the benchmark library's, not smg's).")
    load = []
    if "loadavg_start" in c:
        load.append(f"load average at the start {c['loadavg_start']}")
    elif "loadavg_before" in res.load:
        load.append(f"load average before {res.load['loadavg_before']}")
    if "loadavg_after" in res.load:
        load.append(f"after {res.load['loadavg_after']}")
    elif "loadavg_after" in c:
        load.append(f"after {c['loadavg_after']}")
    others = [b.get("others_cpus") for b in res.rows if isinstance(b.get("others_cpus"), (int, float))]
    if others:
        load.append(f"other processes kept {fmt(min(others))}–{fmt(max(others))} of the "
                    f"{cpus} CPUs busy while the rows ran (column `others`)")
    out.append("*Load:* " + ("; ".join(load) if load else "not recorded") + ".")
    if c.get("note"):  # a caveat recorded with the run (bench_torch.py --note)
        out.append(f"*Note:* {c['note']}")
    if module == "torch":
        cpu = "bench_torch.py measures wall time only (no CPU column)"
    elif "smg_cpu_time" in c:
        cpu = ("`cpu` is the process CPU time over all threads per iteration (Google Benchmark's "
               "MeasureProcessCPUTime), beside the wall time (UseRealTime); `cpu/wall` near the "
               "thread count means the threads had the CPUs to themselves")
    else:
        cpu = ("`cpu` is Google Benchmark's default CPU time (main thread only) — a run from before "
               "the process-CPU convention; re-run to get it")
    counts = ", ".join(f"{n} row{'s' if n > 1 else ''} {r} repetition{'s' if r > 1 else ''}"
                       for r, n in sorted(res.reps.items(), reverse=True))
    if res.aggregated:
        proto = (f"*Noise protocol:* {counts}; a repeated row shows the median of its repetitions "
                 f"(times and counters) and, as `wall min`, its fastest repetition; a row run once "
                 f"is a single measurement (scripts/bench.sh --reps N repeats every row); {cpu}.")
    else:
        proto = (f"*Noise protocol:* one repetition per row (a single measurement: no median or "
                 f"min; scripts/bench.sh --reps N repeats every row); {cpu}.")
    out.append(proto)
    return " ".join(out[:1]) + "\n\n" + "\n".join(f"- {x}" for x in out[1:]) + "\n"


def table(res, with_cpu=True):
    rows = res.rows
    counters = []
    for b in rows:
        for k in b:
            if (k not in RESERVED and k not in counters and k not in LOAD_COUNTERS
                    and isinstance(b[k], (int, float))):
                counters.append(k)
    integer = {k: all(isinstance(b.get(k), (int, float)) and math.isfinite(b[k])
                      and float(b[k]).is_integer() for b in rows if k in b) for k in counters}
    for k in counters:  # error columns are never integers, even when they are 0
        if k.startswith("err"):
            integer[k] = False
    has_min = bool(res.mins)
    has_others = any("others_cpus" in b for b in rows)
    head = ["benchmark", "wall"] + (["wall min"] if has_min else []) + (["cpu", "cpu/wall"] if with_cpu else [])
    head += ["others [CPUs]"] if has_others else []
    head += [f"{k} [{unit_of(k)}]" if unit_of(k) else k for k in counters]
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    for b in rows:
        if b.get("error_occurred"):
            out.append("| " + " | ".join([b["clean"], "error: " + b.get("error_message", "")]
                                         + [""] * (len(head) - 2)) + " |")
            continue
        u = b.get("time_unit", "ns")
        row = [b["clean"], f"{fmt_time(b['real_time'])} {u}"]
        if has_min:
            m = res.min_of(b)
            row.append(f"{fmt_time(m)} {u}" if m is not None else "")
        if with_cpu:
            row.append(f"{fmt_time(b['cpu_time'])} {u}")
            row.append(fmt(b["cpu_time"] / b["real_time"]) if b.get("real_time") else "n/a")
        if has_others:
            row.append(fmt(b.get("others_cpus")) if "others_cpus" in b else "")
        row += [fmt(b.get(k), integer[k]) if k in b else "" for k in counters]
        out.append("| " + " | ".join(row) + " |")
    return "\n".join(out) + "\n"


# ---- generated summaries ------------------------------------------------------------------------
def ms(b):
    """A row's median wall time in milliseconds."""
    scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
    return b["real_time"] * scale


def threads_of(b, where=r"threads:(\d+)"):
    """A row's thread count: `threads:N` in its name (skin's rows end in `/N`: where=r"/(\d+)$")."""
    m = re.search(where, b["clean"])
    return int(m.group(1)) if m else None


def max_threads_row(res, pattern, where=r"threads:(\d+)"):
    rows = res.find(pattern)
    return max(rows, key=lambda b: threads_of(b, where) or 0) if rows else None


def summary_energy(res):
    s = []
    for prec in ("float", "double"):
        t = max_threads_row(res, rf"^BM_carap_plus_lrm<{prec}>")
        if not t:
            continue
        th = threads_of(t)
        parts = [f"C-ARAP + LRM with gradients, {prec}, {th} thread(s): **{fmt(ms(t))} ms** "
                 f"(median wall; cpu/wall {fmt(t['cpu_time'] / t['real_time'])})"]
        if prec == "float" and "target_ms" in t:
            verdict = "met" if ms(t) <= t["target_ms"] else "missed"
            parts.append(f"the {fmt(t['target_ms'])} ms target is {verdict}")
        c = res.one(rf"^BM_carap<{prec}, true>/threads:{th}$")
        l1 = res.one(rf"^BM_lrm<{prec}, 1>/threads:{th}$")
        if c and l1:
            parts.append(f"the separate rows: C-ARAP + gradient {fmt(ms(c))} ms, LRM + exact gradient "
                         f"{fmt(ms(l1))} ms (sum {fmt(ms(c) + ms(l1))} ms)")
        if prec == "float" and "err_vs_double" in t:
            parts.append(f"float-vs-double gradient error {fmt(t['err_vs_double'])} on identical "
                         f"(float-representable) inputs; rounding the inputs to float alone changes "
                         f"the double gradient by {fmt(t.get('err_input_rounding'))}")
        s.append("; ".join(parts) + ".")
    one = [b for b in res.find(r"^BM_(carap|lrm|arap)<") if threads_of(b) == 1]
    if one:
        costs = ", ".join(f"`{b['clean'].split('/')[0]}` {fmt(b['ns_per_term'])} ns"
                          for b in one if "ns_per_term" in b and "<float" in b["clean"])
        if costs:
            s.append(f"Per-term cost, float, 1 thread (wall time per term): {costs}.")
    for name in ("carap", "lrm"):
        ad = res.one(rf"^BM_autodiff_{name}")
        if ad and "ad_ratio" in ad:
            s.append(f"AutoDiffScalar per term, {name.upper().replace('CARAP', 'C-ARAP')}: "
                     f"{fmt(ad['ad_ratio'])}× the analytic kernel's time on the same sub-problem "
                     f"(gradients agree to {fmt(ad.get('err_vs_analytic'))}).")
    d = res.one(r"^BM_lrm<double, 2>")
    if d and "err_detach_vs_exact" in d:
        e = res.one(rf"^BM_lrm<double, 1>/threads:{threads_of(d)}$")
        cost = f" at {fmt(ms(d))} ms against {fmt(ms(e))} ms exact" if e else ""
        s.append(f"Holding ω constant changes the LRM gradient by {fmt(100 * d['err_detach_vs_exact'])} % "
                 f"on this scene{cost}.")
    s += locality_lines(res)
    return s


def locality_lines(res):
    s = []
    for b in sorted(res.find(r"^locality/.*/random/"), key=lambda r: r["clean"]):
        m = res.one("^" + re.escape(b["clean"].replace("/random/", "/morton/")) + "$")
        if not m:
            continue
        what = b["clean"].split("/")[1]
        line = (f"Node order, `{what}` {b['clean'].split('/')[-1]}: random order {fmt(ms(b))} ms, "
                f"Morton order {fmt(ms(m))} ms (medians): speed-up of the sorted order "
                f"**{fmt(ms(b) / ms(m))}×**")
        ratios = [ms(b) / ms(m)]
        bmin, mmin = res.min_of(b), res.min_of(m)
        if bmin and mmin:
            ratios.append(bmin / mmin)
            line += f", {fmt(ratios[-1])}× on the fastest repetitions"
        if b.get("cpu_time") and m.get("cpu_time"):
            ratios.append(b["cpu_time"] / m["cpu_time"])
            line += f", {fmt(ratios[-1])}× in process CPU time"
        if min(ratios) < 1 < max(ratios):
            line += " (the measures disagree in sign: within this run's noise)"
        line += (f"; mean |i − j| over edges {fmt(b.get('mean_edge_span'))} → "
                 f"{fmt(m.get('mean_edge_span'))}; energies equal to "
                 f"{fmt(max(b.get('energy_vs_input_order', 0), m.get('energy_vs_input_order', 0)))}.")
        s.append(line)
    return s


def param(res, name):
    m = re.search(rf"(?:^| ){name}=(\S+)", res.context.get("smg_params", ""))
    return m.group(1) if m else None


def summary_core(res):
    s = []
    batch = float(param(res, "n") or 1024)
    ns = {"ns": 1.0, "us": 1e3, "ms": 1e6, "s": 1e9}
    for fn in ("exp", "log", "rotate"):
        for jac in ("false", "true"):
            d = res.one(rf"^BM_{fn}<double, {jac}>")
            f = res.one(rf"^BM_{fn}<float, {jac}>")
            if d and f and "ns_per_call" in d and "ns_per_call" in f:
                cd = d["cpu_time"] * ns[d.get("time_unit", "ns")] / batch
                cf = f["cpu_time"] * ns[f.get("time_unit", "ns")] / batch
                s.append(f"`{fn}`{' with Jacobians' if jac == 'true' else ''}: double "
                         f"{fmt(d['ns_per_call'])} ns, float {fmt(f['ns_per_call'])} ns per call "
                         f"(wall; in CPU time {fmt(cd)} and {fmt(cf)} ns); "
                         f"float error {fmt(f.get('err_vs_double'))} on identical inputs.")
    return s


def summary_torch(res):
    s = []
    for b in res.rows:
        if isinstance(b.get("speedup"), (int, float)) and math.isfinite(b["speedup"]):
            s.append(f"{b['name']}: smg_torch {fmt(b['real_time'])} {b.get('time_unit', 'ms')}, "
                     f"PyTorch autograd {fmt(b.get('pytorch_ms'))} ms — {fmt(b['speedup'])}× faster.")
        elif "pytorch_ms" in b:
            s.append(f"{b['name']}: smg_torch {fmt(b['real_time'])} {b.get('time_unit', 'ms')}"
                     + ("." if "pytorch_note" in b else "; no PyTorch reference at this size."))
        if isinstance(b.get("compile_speedup"), (int, float)) and math.isfinite(b["compile_speedup"]):
            s[-1] = s[-1][:-1] + (f"; torch.compile {fmt(b['compile_ms'])} ms after "
                                  f"{fmt(b['compile_time_s'])} s of compiling — {fmt(b['compile_speedup'])}× faster.")
        # why a peer has no number (torch.compile missing, a size skipped): the scripts' notes
        label = {"smg_note": "smg_torch", "pytorch_note": "PyTorch autograd", "compile_note": "torch.compile"}
        notes = [v if v.startswith(label.get(k, k)) else f"{label.get(k, k)} {v}"
                 for k, v in b.items() if k.endswith("_note") and isinstance(v, str)]
        if notes:
            s.append(f"{b['name']}: " + "; ".join(notes) + ".")
    return s


SUMMARIES = {"energy": summary_energy, "core": summary_core, "torch": summary_torch}


def torch_baseline(d):
    path = os.path.join(d, "torch.json")
    if not os.path.exists(path):
        return ""
    res = Result(path)
    rows = [b for b in res.rows if b["name"].startswith("energies")]
    if not rows:
        return ""
    out = [f"**PyTorch autograd baseline** (from `bench/torch/bench_torch.py`, "
           f"`bench/results/torch.json`, measured {res.context.get('date', '?')}; not Google "
           f"Benchmark — best of {rows[0].get('iterations', '?')} calls; see the torch section): the same "
           f"energies forward + backward through `smg_torch` against vectorised pure-PyTorch "
           f"autograd.\n",
           "| row | smg_torch | PyTorch autograd | speed-up |", "|---|---:|---:|---:|"]
    for b in rows:
        out.append(f"| {b['name']} | {fmt(b['real_time'])} {b.get('time_unit', 'ms')} | "
                   f"{fmt(b.get('pytorch_ms'))} ms | {fmt(b.get('speedup'))}× |")
    return "\n".join(out) + "\n"


def section(module, files, d):
    out = []
    notes = os.path.join(HERE, "notes", module + ".md")
    if os.path.exists(notes):
        with open(notes) as f:
            out.append(f.read().rstrip() + "\n")
    else:
        out.append(f"## {module}\n")
    for name in files:
        res = Result(os.path.join(d, name + ".json"))
        raw = f"bench/results/{name}.json"
        if name != module:
            out.append(f"### {module}: `{res.context.get('smg_params', name)}` (`{name}.json`)\n")
        elif len(files) > 1:
            out.append(f"### {module}: `{res.context.get('smg_params', 'default parameters')}`\n")
        out.append(header(res, module, raw))
        summary = SUMMARIES.get(module, lambda r: [])(res)
        if summary:
            out.append("**Summary** (generated from this run's numbers):\n\n"
                       + "\n".join(f"- {x}" for x in summary) + "\n")
        out.append(table(res, with_cpu=module != "torch"))
    if module == "energy":
        out.append(per_term_comparison(files, d))
        out.append(torch_baseline(d))
    return "\n".join(x for x in out if x) + "\n"


def per_term_comparison(files, d):
    """Per-term cost of the same rows at every size that was run."""
    if len(files) < 2:
        return ""
    # One result per problem size (a rerun of some rows at the same size, such as the
    # interleaved locality run, measures noise, not size).
    results, sizes = [], set()
    for n in files:
        r = Result(os.path.join(d, n + ".json"))
        size = tuple(param(r, k) for k in ("n", "t", "k", "gaps"))
        if size not in sizes:
            sizes.add(size)
            results.append((n, r))
    if len(results) < 2:
        return ""
    names = []
    for _, r in results:
        for b in r.rows:
            if "ns_per_term" in b and b["clean"] not in names and b["clean"].startswith(("BM_", "locality")):
                names.append(b["clean"])
    names = [n for n in names if sum(1 for _, r in results if r.one("^" + re.escape(n) + "$")) > 1]
    if not names:
        return ""
    def others(r):
        v = sorted(b["others_cpus"] for b in r.rows if isinstance(b.get("others_cpus"), (int, float)))
        return fmt(v[len(v) // 2]) if v else "?"
    out = ["### energy: per-term cost at each size (ns per term, median wall time / terms)\n",
           "Each column is one run (`N/T/K/gaps`, and the median over its rows of the CPUs other "
           "processes kept busy: compare columns run under similar load).\n",
           "| row | " + " | ".join(f"`{n}.json`: {param(r, 'n')}/{param(r, 't')}/{param(r, 'k')}/"
                                    f"{param(r, 'gaps')}, others {others(r)}" for n, r in results) + " |",
           "|---|" + "---:|" * len(results)]
    for n in names:
        cells = []
        for _, r in results:
            b = r.one("^" + re.escape(n) + "$")
            cells.append(fmt(b["ns_per_term"]) if b and "ns_per_term" in b else "")
        out.append(f"| {n} | " + " | ".join(cells) + " |")
    lines = []
    (n0, r0), rest = results[0], results[1:]
    for key in ("BM_carap<float, true>/threads:1", "BM_lrm<float, 1>/threads:1",
                "locality/carap_grad<float>/random/threads:1", "locality/carap_grad<float>/morton/threads:1",
                "locality/lrm_grad<float>/random/threads:1", "locality/lrm_grad<float>/morton/threads:1"):
        b0 = r0.one("^" + re.escape(key) + "$")
        for n1, r1 in rest:
            b1 = r1.one("^" + re.escape(key) + "$")
            if b0 and b1 and b0.get("ns_per_term") and b1.get("ns_per_term"):
                lines.append(f"`{key}`: {fmt(b0['ns_per_term'])} ns per term in `{n0}.json`, "
                             f"{fmt(b1['ns_per_term'])} ns in `{n1}.json` "
                             f"(×{fmt(b1['ns_per_term'] / b0['ns_per_term'])}).")
    if lines:
        out.append("\nFrom the table:\n\n" + "\n".join(f"- {x}" for x in lines))
    return "\n".join(out) + "\n"


# ---- README highlights (bench/report.py --highlights / --readme) --------------------------------
REPO = os.path.dirname(HERE)
HIGHLIGHTS_BEGIN = "<!-- smg:highlights begin -->"
HIGHLIGHTS_END = "<!-- smg:highlights end -->"
# issue 6's target for the splatter (forward + backward, 320x240, 100k Gaussians, 2 threads); the
# energy target travels in the JSON as the counter target_ms.
SPLAT_TARGET_MS = 150.0
# What each variant of the ablation ladder uses (docs/trainer.md, "Variants"): graph, rigidity, LRM.
LADDER_VARIANTS = {"base": ("geometric", "—", "—"), "mosca": ("geometric", "ARAP", "—"),
                   "smg-only": ("semantic", "ARAP", "—"), "no-carap": ("semantic", "ARAP", "yes"),
                   "no-lrm": ("semantic", "C-ARAP", "—"), "full": ("semantic", "C-ARAP", "yes")}
# The paired differences quoted (scripts/ladder_report.py writes them all to docs/results.md).
LADDER_PAIRS = [("full", "no-lrm"), ("full", "no-carap"), ("smg-only", "mosca"), ("smg-only", "base")]


def fmt_ms(value):
    """A time in milliseconds, in s from 1000 ms on."""
    return f"{fmt(value / 1e3)} s" if value >= 1e3 else f"{fmt(value)} ms"


def cpu_ms(b):
    scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
    return b["cpu_time"] * scale


def load_result(d, name):
    path = os.path.join(d, name + ".json")
    return Result(path) if os.path.exists(path) else None


def hl_core(res):
    batch = float(param(res, "n") or 1024)
    ns = {"ns": 1.0, "us": 1e3, "ms": 1e6, "s": 1e9}
    names = {("exp", "true"): " + Jr", ("log", "true"): " + Jr⁻¹", ("rotate", "true"): " + both Jacobians"}
    out = []
    for fn in ("exp", "log", "rotate"):
        for jac in ("false", "true"):
            d = res.one(rf"^BM_{fn}<double, {jac}>")
            f = res.one(rf"^BM_{fn}<float, {jac}>")
            if not (d and f and "ns_per_call" in d and "ns_per_call" in f):
                continue
            cd = d["cpu_time"] * ns[d.get("time_unit", "ns")] / batch
            cf = f["cpu_time"] * ns[f.get("time_unit", "ns")] / batch
            out.append(f"| `so3::{fn}`{names.get((fn, jac), '')} | {fmt(d['ns_per_call'])} / {fmt(cd)} | "
                       f"{fmt(f['ns_per_call'])} / {fmt(cf)} | {fmt(f.get('err_vs_double'))} |")
    if not out:
        return []
    return [f"**core** (`bench/results/core.json`; a batch of {int(batch)} random inputs; wall / process "
            f"CPU time per call; float's largest relative error against double on the same inputs):", "",
            "| operation | double ns/call | float ns/call | float error vs double |",
            "|---|---:|---:|---:|"] + out + [""]


def hl_graph(res):
    sizes, frames = [], []
    for b in res.find(r"^knn/double/\d+/\d+"):
        n, t = (int(x) for x in b["clean"].split("/")[2:4])
        if n not in sizes:
            sizes.append(n)
        if t not in frames:
            frames.append(t)
    if not sizes:
        return []
    sizes.sort()
    frames.sort()
    rows = []
    for n in sizes:
        cells = []
        for t in frames:
            b = res.one(rf"^knn/double/{n}/{t}/")
            cell = f"{fmt_ms(ms(b))} ({fmt_ms(cpu_ms(b))} CPU)" if b else "—"
            bf = res.one(rf"^knn_brute_force/double/{n}/{t}/")
            if b and bf:
                cell += f"; brute force {fmt_ms(ms(bf))}"
            cells.append(cell)
        big = res.one(rf"^knn/double/{n}/{frames[-1]}/")
        rss = f"{fmt(big['peak_rss_mb'])} MB" if big and "peak_rss_mb" in big else "—"
        rows.append(f"| {n:,} | ".replace(",", " ") + " | ".join(cells) + f" | {rss} |")
    knn = res.find(r"^knn/")
    mismatched = sum(int(b.get("mismatched_rows", 0)) for b in knn)
    checked = sum(int(b.get("checked_rows", 0)) for b in knn)
    return [f"**graph** (`bench/results/graph.json`; exact trajectory KNN, k = {param(res, 'k')}, double, "
            f"one build on all threads; wall time and process CPU time over all threads; "
            f"{mismatched} rows differ from brute force over the {checked} checked):", "",
            "| N | " + " | ".join(f"T = {t}" for t in frames) + f" | peak RSS (T = {frames[-1]}) |",
            "|---:|" + "---:|" * (len(frames) + 1)] + rows + [""]


def hl_energy(res):
    t = max_threads_row(res, r"^BM_carap_plus_lrm<float>")
    if not t:
        return []
    th = threads_of(t)
    line = (f"**energy** (`bench/results/energy.json`; N = {param(res, 'n')}, T = {param(res, 't')}, "
            f"K = {param(res, 'k')}, gaps {{{param(res, 'gaps').replace(',', ', ')}}}): C-ARAP + LRM energy "
            f"and exact gradient, float, {th} threads: **{fmt_ms(ms(t))}** wall ({fmt_ms(cpu_ms(t))} "
            f"process CPU)")
    if "target_ms" in t:
        verdict = "met" if ms(t) <= t["target_ms"] else "missed"
        line += f"; the {fmt_ms(t['target_ms'])} target is {verdict} on this run"
    d = res.one(rf"^BM_carap_plus_lrm<double>/threads:{th}$")
    if d:
        line += f"; double {fmt_ms(ms(d))}"
    if "err_vs_double" in t:
        line += f"; float against double, gradient relative error {fmt(t['err_vs_double'])}"
    line += "."
    ads = []
    for name, title in (("carap", "C-ARAP"), ("lrm", "LRM")):
        ad = res.one(rf"^BM_autodiff_{name}")
        if ad and "ad_ratio" in ad:
            ads.append(f"{fmt(ad['ad_ratio'])}× ({title})")
    if ads:
        line += (" Against Eigen's AutoDiffScalar on the same maths the analytic gradients are "
                 + " and ".join(ads) + " faster.")
    dl = res.one(r"^BM_lrm<double, 2>")
    if dl and "err_detach_vs_exact" in dl:
        line += f" Holding ω constant changes the LRM gradient by {fmt(100 * dl['err_detach_vs_exact'])} %."
    return [line, ""]


def hl_skin(res):
    def rate(prec, method, th, kind="BM_blend"):
        b = res.one(rf"^{kind}<{prec}, SkinMethod::{method}>/{th}$")
        return b.get("blend_rate") if b else None

    parts, ratios = [], []
    for method in ("dqb", "lbs"):
        cells = []
        for prec in ("double", "float"):
            r1, r2 = rate(prec, method, 1), rate(prec, method, 2)
            if r1 and r2:
                cells.append(f"{fmt(r1 / 1e6)} M ({fmt(r2 / 1e6)} M) in {prec}")
            for th in (1, 2):
                a, b = rate(prec, "dqb", th), rate(prec, "lbs", th)
                if method == "lbs" and a and b:
                    ratios.append(b / a)
        if cells:
            parts.append(f"{method.upper()} {', '.join(cells)}")
    if not parts:
        return []
    points = f"{int(param(res, 'points') or 0):,}".replace(",", " ")
    line = (f"**skin** (`bench/results/skin.json`; {points} points × {int(param(res, 'k') or 0) + 1} "
            f"drivers; point×driver blends per second of wall time on one thread, two in brackets): "
            + "; ".join(parts) + ".")
    if ratios:
        line += (f" LBS's rate is {min(ratios):.2f}–{max(ratios):.2f}× DQB's over these four "
                 f"configurations.")
    j = rate("double", "dqb", 1, "BM_blend_jacobians")
    if j:
        line += f" With every Jacobian block: {fmt(j / 1e6)} M (double, DQB, one thread)."
    bw = max_threads_row(res, r"^BM_backward<double, SkinMethod::dqb>", r"/(\d+)$")
    if bw:
        th = threads_of(bw, r"/(\d+)$")
        line += f" Backward into nodes and points: {fmt_ms(ms(bw))} (double, {th} threads)."
    twists = sorted({int(b["clean"].split("/")[1]) for b in res.find(r"^BM_twist/\d+/0$")})
    vols = []
    for th in twists:
        b = res.one(rf"^BM_twist/{th}/0$")
        if b and "vol_ratio_dqb" in b and "vol_ratio_lbs" in b:
            vols.append(f"{th}°: DQB {fmt(b['vol_ratio_dqb'])}, LBS {fmt(b['vol_ratio_lbs'])}")
    if vols:
        line += " Volume of a twisting tube after/before (" + "; ".join(vols) + ")."
    return [line, ""]


def hl_splat(res):
    fb2 = res.one(r"^forward_backward/W:320/H:240/G:100000/threads:2$")
    if not fb2:
        return []
    verdict = "met" if ms(fb2) <= SPLAT_TARGET_MS else "missed"
    line = (f"**splat** (`bench/results/splat.json`; float, 100k Gaussians): forward + backward at "
            f"320×240 on 2 threads **{fmt_ms(ms(fb2))}** wall ({fmt_ms(cpu_ms(fb2))} process CPU); the "
            f"{fmt_ms(SPLAT_TARGET_MS)} target is {verdict} on this run")
    fb1 = res.one(r"^forward_backward/W:320/H:240/G:100000/threads:1$")
    if fb1:
        line += f"; 1 thread {fmt_ms(ms(fb1))}"
    line += (". The double-precision splatter is checked against an independent PyTorch autograd "
             "statement of gsplat's maths (`tests/reference/`).")
    return [line, ""]


def hl_torch(d):
    rows = []
    cpu = load_result(d, "torch")
    if cpu:
        for b in cpu.rows:
            if isinstance(b.get("speedup"), (int, float)) and math.isfinite(b["speedup"]):
                rows.append(f"| CPU | {b['name']} | {fmt_ms(b['real_time'])} | {fmt_ms(b['pytorch_ms'])} | "
                            f"{fmt(b['speedup'])}× |")
    gpu_path = os.path.join(d, "gpu", "torch_cuda_h100.json")
    device = None
    if os.path.exists(gpu_path):
        with open(gpu_path) as f:
            gpu = json.load(f)
        device = gpu.get("context", {}).get("device")
        for b in gpu.get("benchmarks", []):
            if isinstance(b.get("speedup"), (int, float)) and math.isfinite(b["speedup"]):
                rows.append(f"| {b.get('device', device)} | {b['name']} | {fmt_ms(b['real_time'])} | "
                            f"{fmt_ms(b['pytorch_ms'])} | {fmt(b['speedup'])}× |")
    if not rows:
        return []
    # A caveat recorded with the CPU run goes before the table, where a reader of the speed-ups sees it.
    note = cpu.context.get("note") if cpu else None
    caveat = [f"**CPU caveat:** {note}", ""] if note else []
    return ["**smg_torch against pure-PyTorch autograd** (forward + backward of the same equations; "
            "`bench/results/torch.json`" + (", `bench/results/gpu/torch_cuda_h100.json`" if device else "")
            + "; best time; [docs/torch.md](docs/torch.md), [docs/cuda.md](docs/cuda.md)):", ""] + caveat + [
            "| device | operation | smg_torch | PyTorch autograd | speed-up |",
            "|---|---|---:|---:|---:|"] + rows + [""]


def md_section(text, name):
    begin, end = f"<!-- ladder:{name} -->", f"<!-- /ladder:{name} -->"
    if begin not in text or end not in text:
        return None
    return text[text.index(begin):text.index(end)]


def md_table(text, first_cell):
    """The first Markdown table whose header starts with `first_cell`: (header cells, rows)."""
    lines = text.split("\n")
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == first_cell:
            rows = []
            for row in lines[i + 2:]:
                if not row.startswith("|"):
                    break
                rows.append([c.strip() for c in row.strip().strip("|").split("|")])
            return cells, rows
    return None, []


def ladder_tables(results_md):
    """The ablation ladder of RESULTS_MD: (scenes, means, paired, seeds, EPE column), or None.

    means[scene][variant] and paired[scene]["A − B"] are the rows of the scene's tables as
    {column: cell}; seeds[scene] is how many seeds its per-seed table has."""
    if not os.path.exists(results_md):
        return None
    with open(results_md, encoding="utf-8") as f:
        text = f.read()
    scenes, means, paired, seeds = [], {}, {}, {}
    for scene in ("standard", "occluder"):
        sec = md_section(text, scene)
        if sec is None:
            continue
        head, rows = md_table(sec, "variant")
        if not head:
            continue
        scenes.append(scene)
        means[scene] = {r[0]: dict(zip(head, r)) for r in rows}
        phead, prows = md_table(sec, "A − B")
        paired[scene] = {r[0]: dict(zip(phead, r)) for r in prows} if phead else {}
        shead = [h for h in (md_table(sec.split("Per seed", 1)[-1], "variant")[0] or []) if h.startswith("seed ")]
        seeds[scene] = len(shead)
    if not scenes:
        return None
    # The query EPE (surface query tracks, what Dycheck and Shape-of-Motion report) where the ladder
    # has it; ladders generated before issue 33 have node EPE only, titled "3D EPE (m)".
    # The same column for every scene: the query EPE only where every scene's ladder has it.
    # Ladders written before issue 33 title node EPE "3D EPE (m)": the same column under its new name.
    for s in scenes:
        for row in list(means[s].values()) + list(paired[s].values()):
            if "3D EPE (m)" in row:
                row.setdefault("node EPE (m)", row["3D EPE (m)"])
    firsts = [next(iter(means[s].values())) for s in scenes]
    epe = "query EPE (m)" if all("query EPE (m)" in f for f in firsts) else "node EPE (m)"
    return scenes, means, paired, seeds, epe


def hl_ladder(results_md):
    tables = ladder_tables(results_md)
    if tables is None:
        return []
    scenes, means, paired, seeds, epe = tables
    title = epe
    cols = (epe, "masked PSNR (dB)")
    variants = list(means[scenes[0]])
    head = ("| variant | graph | rigidity | LRM | "
            + " | ".join(f"{s}: {title} | {cols[1]}" for s in scenes) + " |")
    out = [f"**ablation ladder** (`docs/results.md`, written by `scripts/ladder.sh`; "
           f"{' and '.join(f'{seeds[s]} seeds on the {s} scene' for s in scenes)}, mean ± 95 % "
           f"interval; every seed is a different scene):", "", head,
           "|---|---|---|---|" + "---:|" * (2 * len(scenes))]
    for v in variants:
        desc = LADDER_VARIANTS.get(v, ("?", "?", "?"))
        cells = [means[s].get(v, {}).get(c, "—") for s in scenes for c in cols]
        out.append(f"| {v} | " + " | ".join(desc) + " | " + " | ".join(cells) + " |")
    out.append("")
    lines = []
    for a, b in LADDER_PAIRS:
        key = f"{a} − {b}"
        row = {s: paired[s].get(key) for s in scenes if paired[s].get(key)}
        if not row:
            continue
        what = next(iter(row.values())).get("isolates", "")
        per = "; ".join(f"{s}: {r.get(cols[0], '—')}" for s, r in row.items())
        lines.append(f"- {what} (`{key}`), {title[:-4]} in m: {per}")
    if lines:
        out += ["Paired differences A − B over the same seeds (mean ± 95 % interval; in brackets, on how "
                "many seeds A is better):", ""] + lines + [""]
    return out


# ---- the README's short form: one headline line per subject, each with its links -----------------
def short_energy(res):
    t = max_threads_row(res, r"^BM_carap_plus_lrm<float>")
    if not t:
        return None
    line = (f"- **Regularisers on the CPU** (`bench/results/energy.json`; N = {param(res, 'n')} nodes, "
            f"T = {param(res, 't')} frames, K = {param(res, 'k')}): C-ARAP + LRM energy and exact "
            f"gradient, float, {threads_of(t)} threads: **{fmt_ms(ms(t))}** wall ({fmt_ms(cpu_ms(t))} "
            f"process CPU")
    if "target_ms" in t:
        verdict = "met" if ms(t) <= t["target_ms"] else "missed"
        line += f"; the {fmt_ms(t['target_ms'])} target is {verdict} on this run"
    line += ")"
    ads = []
    for name, title in (("carap", "C-ARAP"), ("lrm", "LRM")):
        ad = res.one(rf"^BM_autodiff_{name}")
        if ad and "ad_ratio" in ad:
            ads.append(f"{fmt(ad['ad_ratio'])}× ({title})")
    if ads:
        line += "; the analytic gradients are " + " and ".join(ads) + " faster than Eigen's AutoDiffScalar"
    return line + "."


def short_splat(res):
    fb2 = res.one(r"^forward_backward/W:320/H:240/G:100000/threads:2$")
    if not fb2:
        return None
    verdict = "met" if ms(fb2) <= SPLAT_TARGET_MS else "missed"
    return (f"- **Reference splatter on the CPU** (`bench/results/splat.json`; float, 100k Gaussians, "
            f"320×240): forward + backward on 2 threads **{fmt_ms(ms(fb2))}** wall ({fmt_ms(cpu_ms(fb2))} "
            f"process CPU; the {fmt_ms(SPLAT_TARGET_MS)} target is {verdict} on this run); in double it is "
            f"checked against an independent PyTorch autograd statement of gsplat's maths (`tests/reference/`).")


def short_torch(d):
    """smg_torch's energies row: the GPU run's where there is one (the CPU run's speed-ups may carry
    a caveat, which its rows keep in docs/performance.md), else the CPU run's at the most threads."""
    cpu = load_result(d, "torch")
    note = " (with the run's caveat)" if cpu and cpu.context.get("note") else ""
    gpu_path = os.path.join(d, "gpu", "torch_cuda_h100.json")
    if os.path.exists(gpu_path):
        with open(gpu_path) as f:
            gpu = json.load(f)
        rows = [b for b in gpu.get("benchmarks", [])
                if isinstance(b.get("speedup"), (int, float)) and math.isfinite(b["speedup"])]
        b = next((r for r in rows if r["name"].startswith("energies")), rows[0] if rows else None)
        if b:
            device = b.get("device", gpu.get("context", {}).get("device", "GPU"))
            return (f"- **smg_torch on a GPU** ({device}, `bench/results/gpu/torch_cuda_h100.json`): {b['name']}, "
                    f"**{fmt_ms(b['real_time'])}** against {fmt_ms(b['pytorch_ms'])} for pure-PyTorch autograd "
                    f"of the same equations ({fmt(b['speedup'])}×); every operator: [docs/cuda.md](docs/cuda.md); "
                    f"the CPU rows{note}: [docs/performance.md](docs/performance.md).")
    if cpu:
        rows = [b for b in cpu.rows if isinstance(b.get("speedup"), (int, float)) and math.isfinite(b["speedup"])]
        b = next((r for r in reversed(rows) if r["name"].startswith("energies")), rows[0] if rows else None)
        if b:
            return (f"- **smg_torch on the CPU** (`bench/results/torch.json`): {b['name']}, "
                    f"**{fmt_ms(b['real_time'])}** against {fmt_ms(b['pytorch_ms'])} for pure-PyTorch autograd "
                    f"of the same equations ({fmt(b['speedup'])}×); every row{note}: "
                    f"[docs/performance.md](docs/performance.md).")
    return None


def short_ladder(results_md):
    tables = ladder_tables(results_md)
    if tables is None:
        return None
    scenes, means, paired, seeds, epe = tables
    first, last = "base", "full"

    def mean(scene, variant):
        return means[scene].get(variant, {}).get(epe, "—").split(" ±")[0]

    line = (f"- **Ablation ladder** (`docs/results.md`; "
            f"{' and '.join(f'{seeds[s]} seeds on the {s} scene' for s in scenes)}): mean {epe[:-4]} in m "
            f"from `{first}` to `{last}`: "
            + "; ".join(f"{s} {mean(s, first)} → {mean(s, last)}" for s in scenes))
    key = "smg-only − base"
    row = {s: paired[s].get(key) for s in scenes if paired[s].get(key)}
    if row:
        what = next(iter(row.values())).get("isolates", key)
        line += (f". Paired, {what} (`{key}`): " + "; ".join(f"{s} {r.get(epe, '—')}" for s, r in row.items())
                 + " (mean ± 95 % interval; in brackets, on how many seeds A is better)")
    return line + ". Every variant and paired difference: [docs/results.md](docs/results.md)."


def highlights(d, results_md=None, full=False):
    """The README's result highlights (the lines between the markers, without them)."""
    results_md = results_md or os.path.join(REPO, "docs", "results.md")
    found = [r for r in (load_result(d, m) for m in ("core", "graph", "energy", "skin", "splat")) if r]
    dates = sorted({r.context.get("date", "?")[:10] for r in found})
    others = [b["others_cpus"] for r in found for b in r.rows if isinstance(b.get("others_cpus"), (int, float))]
    cpus = {str(r.context.get("num_cpus", "?")) for r in found}
    out = ["<!-- Generated by bench/report.py --readme README.md from bench/results/*.json and "
           "docs/results.md: do not edit by hand (scripts/check_docs.py compares). -->", ""]
    if found:
        out += [f"CPU figures: the published runs in `bench/results/` ({' to '.join(sorted({dates[0], dates[-1]}))}, "
                f"Release, {'/'.join(sorted(cpus))} CPUs"
                + (f", other processes keeping {fmt(min(others))}–{fmt(max(others))} of them busy, so wall "
                   f"times are indicative and process CPU times are given beside them" if others else "")
                + "); every row, its load and its noise protocol: [docs/performance.md](docs/performance.md).", ""]
    by = {m: load_result(d, m) for m in ("core", "graph", "energy", "skin", "splat")}
    if not full:
        # The README's form (its size budget, scripts/check_docs.py): one headline line per
        # subject, each with its links; every table is on the pages they link.
        lines = [short_energy(by["energy"]) if by["energy"] else None,
                 short_splat(by["splat"]) if by["splat"] else None,
                 short_torch(d), short_ladder(results_md)]
        out += [line for line in lines if line]
        return "\n".join(out).rstrip("\n") + "\n"
    every = (("core", hl_core), ("graph", hl_graph), ("energy", hl_energy), ("skin", hl_skin), ("splat", hl_splat))
    for m, fn in every:
        if by[m]:
            out += fn(by[m])
    out += hl_torch(d)
    out += hl_ladder(results_md)
    while out and out[-1] == "":
        out.pop()
    return "\n".join(out) + "\n"


def write_readme(readme, d=None, results_md=None):
    d = d or os.path.join(REPO, "bench", "results")
    with open(readme, encoding="utf-8") as f:
        text = f.read()
    if HIGHLIGHTS_BEGIN not in text or HIGHLIGHTS_END not in text:
        print(f"bench/report.py: {readme} has no '{HIGHLIGHTS_BEGIN}' ... '{HIGHLIGHTS_END}' block",
              file=sys.stderr)
        return 1
    head = text[:text.index(HIGHLIGHTS_BEGIN) + len(HIGHLIGHTS_BEGIN)]
    tail = text[text.index(HIGHLIGHTS_END):]
    new = head + "\n" + highlights(d, results_md) + tail
    if new != text:
        with open(readme, "w", encoding="utf-8") as f:
            f.write(new)
    return 0


def main():
    args = sys.argv[1:]
    if args and args[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    if args and args[0] in ("--highlights", "--highlights-all") and 2 <= len(args) <= 3:
        sys.stdout.write(highlights(args[1], args[2] if len(args) > 2 else None, args[0] == "--highlights-all"))
        return 0
    if args and args[0] == "--readme" and 2 <= len(args) <= 4:
        return write_readme(args[1], args[2] if len(args) > 2 else None,
                            args[3] if len(args) > 3 else None)
    if len(args) != 1 or args[0].startswith("-"):
        print(__doc__, file=sys.stderr)
        return 2
    d = args[0]
    names = [f[:-5] for f in os.listdir(d) if f.endswith(".json")]
    by_module = {}
    for n in names:
        by_module.setdefault(n.split("-", 1)[0], []).append(n)
    modules = sorted(by_module, key=lambda m: (ORDER.index(m) if m in ORDER else len(ORDER), m))
    parts = ["# Performance: speed against error\n",
             "Generated by `bench/report.py` from `bench/results/*.json`; regenerate with "
             "`scripts/bench.sh --publish [MODULE...]`. Problem sizes, gaps, threads, precision and "
             "repetitions are run-time parameters of every binary — flags (`--n=20000 --t=50 --k=8 "
             "--gaps=1 --threads=1,2 --precision=float|double|both --reps=5`; `--smg_help` lists a "
             "binary's) or `SMG_BENCH_*` variables (`SMG_BENCH_N=20000 SMG_BENCH_T=50 SMG_BENCH_K=8 "
             "SMG_BENCH_GAPS=1 scripts/bench.sh --tag large energy`); `scripts/bench.sh` takes "
             "`--filter REGEX`, `--out DIR` (default `build/bench-results`) and touches "
             "`bench/results/` and this page only with `--publish` (bench/README.md). Do not edit by hand: the text of each section lives in "
             "`bench/notes/<module>.md`, and every summary line and number below is generated "
             "from the JSON. Each section states smg's build, the run-time parameters, the load "
             "of the machine during the run and the noise protocol. Times are per benchmark "
             "iteration: `wall` (wall-clock) and `cpu` (process CPU time, all threads); "
             "counters carry their unit in the column header (none: a plain number).\n"]
    for m in modules:
        files = sorted(by_module[m], key=lambda n: (n != m, n))
        parts.append(section(m, files, d))
    for m in NOTES_ONLY:  # sections with no result file of their own
        with open(os.path.join(HERE, "notes", m + ".md")) as f:
            parts.append(f.read().rstrip() + "\n")
    sys.stdout.write("\n".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
