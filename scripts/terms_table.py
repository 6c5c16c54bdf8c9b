#!/usr/bin/env python3
"""The regulariser terms' table of docs/api.md, generated from the code (issue 35: the term list
drives the docs' API table): one row per flag of RegularizerTerms, read from

  - the fused step's list, SMG_REGULARIZER_TERMS (include/smg/energy/term_list.hpp, the
    confidences before it): each flag's options struct and term struct, and so its header in
    include/smg/energy/terms/;
  - that header's top comment: the equation labels (E..);
  - the energy headers: the separate C++ call (a function named for the flag, or node_<flag>s);
  - the same list, from which smg::for_each_term, smg_torch's options and smg_cli regularizers'
    flags are generated, and so the keyword of
    smg_torch.regularizers (examples/torch/smg_torch/__init__.py, which takes its keywords from
    that list: `**terms` checked against REGULARIZER_TERMS);
  - bench/bench_energy.cpp: its BM_<flag> row, or else the row list/<name> that BM_listed gives
    every operator of the list;
  - the CUDA driver (include/smg/cuda/driver.cuh): whether the term runs in the element pass
    (C-ARAP and ARAP, members of ElementTerms, or a term whose struct names its Element, which
    the driver takes from the list) or a phase of its own, and
  - tests/support/operators.hpp: whether the cross-cutting tests' operator list covers it.

  scripts/terms_table.py              print the table
  scripts/terms_table.py --write FILE fill FILE's <!-- terms:begin --> ... <!-- terms:end -->

scripts/check_docs.py fails when docs/api.md's table differs from this output."""
import argparse
import glob
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BEGIN, END = "<!-- terms:begin -->", "<!-- terms:end -->"


def read(rel):
    with open(os.path.join(ROOT, rel), encoding="utf-8") as f:
        return f.read()


def block(text, start, end="\n};"):
    i = text.find(start)
    if i < 0:
        return ""
    j = text.find(end, i)
    return text[i:j if j >= 0 else len(text)]


def top_comment(text):
    lines = []
    for line in text.splitlines():
        if not line.startswith("//"):
            break
        lines.append(line[2:].strip())
    return " ".join(lines)


def labels(comment):
    """The term's own equations: the first (E..) label or range "(E2)-(E6)" its header's top
    comment cites (later ones are references to other equations)."""
    m = re.search(r"\(E(\d+)\)(?:\s*[-–]\s*\(E(\d+)\))?", comment)
    if not m:
        return ""
    return "E%s–E%s" % (m.group(1), m.group(2)) if m.group(2) else "E" + m.group(1)


def member(struct):
    """The name the CUDA driver gives a term's pass: RigidTerm -> rigid (its ElementTerms flag,
    its phase p.rigid)."""
    return struct[:-len("Term")].lower()


def entries():
    """The term list: (flag, options struct, term struct) per entry, the confidences first
    (written by hand in term_list.hpp: ConfidenceOptions, ConfidenceTerm), then one per line of
    SMG_REGULARIZER_TERMS, X(name, Options, Term, on)."""
    lst = block(read("include/smg/energy/term_list.hpp"), "#define SMG_REGULARIZER_TERMS(X)", "\n\n")
    return [("confidence", "ConfidenceOptions", "ConfidenceTerm")] + re.findall(
        r"^\s*X\((\w+),\s*(\w+),\s*(\w+),", lst, re.M)


def rows():
    listed = entries()
    option_type = dict((f, o) for f, o, _ in listed)
    term_list = set(f for f, _, _ in listed)
    headers = {}
    for path in sorted(glob.glob(os.path.join(ROOT, "include/smg/energy/terms/*.hpp"))):
        text = open(path, encoding="utf-8").read()
        for st in re.findall(r"struct (\w+Term) : [^{]*\b(?:TermDefaults|ScratchFree\w*Term)\b", text):
            headers[st] = (os.path.relpath(path, os.path.join(ROOT, "include/smg")), text)
    energy_src = "".join(open(p, encoding="utf-8").read()
                         for p in sorted(glob.glob(os.path.join(ROOT, "include/smg/energy/*.hpp"))))
    torch_init = read("examples/torch/smg_torch/__init__.py")
    # smg_torch.regularizers takes its term keywords from the list (`**terms`, checked against
    # REGULARIZER_TERMS, which _C reads from smg::for_each_term): then every term on the list has
    # its keyword. Otherwise (keywords written by hand) the ones its signature names.
    # (regularizers() hands its checked keywords to _regularizers(), which smg_torch.compat also
    # calls: the loop over the list is there.)
    function = block(torch_init, "def regularizers(", "\n\n\n") + block(torch_init, "def _regularizers(", "\n\n\n")
    signature = block(function, "def regularizers(", ":\n")
    from_list = (re.search(r"\*\*terms\b", signature)
                 and re.search(r"\bfor \w+(?:, \w+)? in REGULARIZER_TERMS\b", function))
    torch_keys = [k for k in term_list if from_list or re.search(r"\b%s=" % k, signature)]
    bench = read("bench/bench_energy.cpp")
    driver = read("include/smg/cuda/driver.cuh")
    element = block(driver, "struct ElementTerms")
    # The element pass runs the terms ElementTerms names ("bool rigid = false;": C-ARAP and ARAP)
    # and every term of the list whose struct names an Element (driver.cuh's ListElements).
    element_members = re.findall(r"bool (\w+) = false", element)
    if "ListElements" in element:
        element_members += [member(s) for _, _, s in listed
                            if "using Element = " in block(headers.get(s, ("", ""))[1], "struct %s " % s)]
    drive = block(driver, "Status drive(", "\n}\n")
    operators = read("tests/support/operators.hpp")
    op_names = set(re.findall(r'static constexpr const char\* name = "(\w+)"', operators))
    # The operator list's term of each operator (bench/bench_energy.cpp's BM_listed gives each one
    # a row list/<name><S>, with no code of its own).
    op_terms = dict((t, n) for n, t in re.findall(
        r'static constexpr const char\* name = "(\w+)";\s*static constexpr const char\* term = "(\w+)"',
        operators))

    out = []
    for flag, _, struct in listed:
        if struct not in headers:
            out.append((flag, None))
            continue
        header, htext = headers.get(struct, ("?", ""))
        call = next((c for c in (flag, "node_%ss" % flag)
                     if re.search(r"[\w>]\s+%s\(" % c, energy_src)), "—")
        if member(struct) in element_members:
            cuda = "element pass"
        elif re.search(r"\bp\.%s\b" % member(struct), drive):
            cuda = "own phase"
        else:
            cuda = "—"
        out.append((flag, dict(
            header="`%s` (`%s`)" % (header, struct),
            eqs=labels(top_comment(htext)) or "—",
            options="`%s`" % option_type[flag] if flag in option_type else "—",
            call="`%s`" % call if call != "—" else call,
            torch="`%s=`" % flag if flag in torch_keys else "—",
            cli="`--terms %s`" % flag if flag in term_list else "—",
            bench=("`BM_%s`" % flag if re.search(r"\bBM_%s\b" % flag, bench)
                   else "`list/%s`" % op_terms[flag] if flag in op_terms and "BM_listed" in bench
                   else "—"),
            cuda=cuda,
            tests="yes" if (flag in op_names or call.strip("`") in op_names
                            or flag + "s" in op_names) else "—")))
    return out


def table():
    lines = ["| `RegularizerTerms::` | term header (struct) | equations | options | separate call | "
             "`smg_torch.regularizers` | `smg_cli regularizers` | bench row | CUDA driver | operator list |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for flag, r in rows():
        if r is None:
            lines.append("| `%s` | (no term configures it) | | | | | | | | |" % flag)
            continue
        lines.append("| `%s` | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            flag, r["header"], r["eqs"], r["options"], r["call"], r["torch"], r["cli"], r["bench"],
            r["cuda"], r["tests"]))
    return "\n".join(lines) + "\n"


def fill(text, body):
    if BEGIN not in text or END not in text:
        return None
    i, j = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:i] + "\n" + body + text[j:]


def main():
    ap = argparse.ArgumentParser(prog="terms_table.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", metavar="FILE", help="fill FILE's terms block")
    a = ap.parse_args()
    body = table()
    if not a.write:
        sys.stdout.write(body)
        return 0
    text = open(a.write, encoding="utf-8").read()
    new = fill(text, body)
    if new is None:
        sys.exit("terms_table.py: %s has no '%s' ... '%s' block" % (a.write, BEGIN, END))
    if new != text:
        with open(a.write, "w", encoding="utf-8") as f:
            f.write(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
