#!/usr/bin/env python3
"""Checks that the documentation's references resolve inside the repository.

Usage: scripts/check_docs.py [REPO_ROOT]   (standard library only; exit 1 on any problem)

(a) every relative link [text](target) in README.md and docs/**/*.md names an existing file;
(b) no tracked file points outside the repository (the parent's shared folder) or cites the
    design notes / interface contract by their original upper-case names instead of
    docs/design.md and docs/interop.md;
(c) equation labels defined in docs/math/*.md are unique across those files (each page has its
    own prefixes: core C Q D, graph G, energy E, skin S, splat R);
(d) every label cited in README.md, docs/**/*.md, bench/notes/*.md and code comments ("(E12)",
    "S1–S19", "(R20)-(R26)") is defined in docs/math; a range's both ends and everything between
    must exist; README's per-page ranges ("docs/math/skin.md, S1–S19") must span the page's
    labels exactly; files under splat/ must not cite skin's S labels and files under skin/ must
    not cite splat's R labels.

Prints one line per problem, "path:line: message", and exits 1 if there are any.
"""

import os
import re
import subprocess
import sys

ROOT = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else
                       os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
SELF = os.path.relpath(os.path.abspath(__file__), ROOT)

problems = []


def problem(path, line, msg):
    problems.append("%s:%d: %s" % (path, line, msg))


def tracked_files():
    try:
        out = subprocess.run(["git", "-C", ROOT, "ls-files", "-z"], check=True,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL).stdout
        return [f for f in out.decode("utf-8", "replace").split("\0") if f]
    except (OSError, subprocess.CalledProcessError):
        files = []
        for d, dirs, names in os.walk(ROOT):
            dirs[:] = [x for x in dirs if x not in (".git", "build") and not x.startswith("build")]
            files += [os.path.relpath(os.path.join(d, n), ROOT) for n in names]
        return files


def read_text(rel):
    try:
        with open(os.path.join(ROOT, rel), "rb") as f:
            data = f.read()
    except OSError:
        return None
    if b"\0" in data[:8192]:
        return None  # binary
    return data.decode("utf-8", "replace")


FILES = sorted(tracked_files())
TEXT = {f: read_text(f) for f in FILES}
TEXT = {f: t for f, t in TEXT.items() if t is not None}

# ---------------------------------------------------------------------------------------------
# (a) relative markdown links
LINK = re.compile(r"!?\[[^\]\n]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^\s*(```|~~~)")


def md_lines(text, strip_code=True):
    """(line number, line) outside fenced code blocks; inline code removed if strip_code."""
    fenced = False
    for n, line in enumerate(text.split("\n"), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            yield n, re.sub(r"`[^`]*`", "", line) if strip_code else line


doc_md = [f for f in TEXT if f.endswith(".md") and (f == "README.md" or f.startswith("docs/"))]
for f in doc_md:
    for n, line in md_lines(TEXT[f]):
        for m in LINK.finditer(line):
            target = m.group(1)
            if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith("#"):
                continue  # URL, mailto:, in-page anchor
            path = target.split("#", 1)[0].split("?", 1)[0]
            resolved = os.path.normpath(os.path.join(os.path.dirname(f), path))
            if resolved.startswith(".."):
                problem(f, n, "link leaves the repository: %s" % target)
            elif not os.path.exists(os.path.join(ROOT, resolved)):
                problem(f, n, "broken link: %s" % target)

# ---------------------------------------------------------------------------------------------
# (b) references outside the repository / to the original upper-case file names
OUTSIDE = re.compile("|".join([r"\.\./" + "shared", "DES" + r"IGN\.md", "INTER" + r"OP\.md",
                               "DA" + r"TA\.md", "CARAP-" + "READING"]))
for f, text in TEXT.items():
    if f == SELF:
        continue
    for n, line in enumerate(text.split("\n"), 1):
        for m in OUTSIDE.finditer(line):
            problem(f, n, "reference outside the repository: %r (use docs/design.md, "
                          "docs/interop.md or describe the source)" % m.group(0))

# ---------------------------------------------------------------------------------------------
# (c) label definitions in docs/math
PREFIXES = "CDQGESR"
LABEL = re.compile(r"\b([%s])(\d{1,2})\b" % PREFIXES)
MATH = sorted(f for f in TEXT if re.match(r"docs/math/[^/]+\.md$", f))

defined = {}  # label -> {file: first line}


def define(label, f, n):
    defined.setdefault(label, {}).setdefault(f, n)


for f in MATH:
    fenced = False
    for n, line in enumerate(TEXT[f].split("\n"), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        spans = []
        stripped = line.strip()
        if stripped.startswith("#"):
            spans.append(stripped)                                   # ## C-ARAP (E7)–(E10)
        spans += re.findall(r"^\s*(?:[-*]\s+)?\*\*([^*]*)\*\*", line)  # **Radius (R7).**
        m = re.match(r"^\s*(?:[-*]\s+)?(\(\w\d{1,2}\)(?:\s*[-–]\s*\(\w\d{1,2}\))?)", line)
        if m:
            spans.append(m.group(1))                                 # - (E2) v̄_i = …
        m = re.search(r"\s(\(\w\d{1,2}\))\s*$", line)
        if m and (fenced or line.startswith("    ")):
            spans.append(m.group(1))                                 # equation tag (S2)
        for span in spans:
            for lm in LABEL.finditer(span):
                define(lm.group(0), f, n)
            # a range in a definition defines what lies between: (R20)-(R26)
            for rm in re.finditer(r"\b([%s])(\d{1,2})\)?\s*[-–]\s*\(?\1(\d{1,2})\b" % PREFIXES,
                                  span):
                for k in range(int(rm.group(2)), int(rm.group(3)) + 1):
                    define("%s%d" % (rm.group(1), k), f, n)

for label, where in sorted(defined.items()):
    if len(where) > 1:
        first = sorted(where.items(), key=lambda kv: kv[0])
        for f, n in first[1:]:
            problem(f, n, "label (%s) also defined in %s:%d" % (label, first[0][0], first[0][1]))

page_of = {}
for label, where in defined.items():
    page_of[label] = sorted(where)[0]

# ---------------------------------------------------------------------------------------------
# (d) cited labels exist
CODE_EXT = (".hpp", ".h", ".cpp", ".cc", ".py", ".sh", ".cmake", ".txt", ".in")
RANGE = re.compile(r"\b([%s])(\d{1,2})\)?\s*[-–]\s*\(?\1?(\d{1,2})\b" % PREFIXES)
COMMENT = re.compile(r"(//|#)(.*)$")


def cited_spans(f, text):
    if f.endswith(".md"):
        if f in MATH or f == "README.md" or f.startswith("docs/") or f.startswith("bench/notes/"):
            for n, line in md_lines(text, strip_code=False):
                yield n, line
        return
    if not (f.endswith(CODE_EXT) or os.path.basename(f) in ("CMakeLists.txt",)):
        return
    if f == SELF:
        return
    for n, line in enumerate(text.split("\n"), 1):
        m = COMMENT.search(line)
        if m and not (m.group(1) == "#" and f.endswith((".hpp", ".h", ".cpp", ".cc"))):
            yield n, m.group(2)
        elif line.lstrip().startswith(("*", "/*")):
            yield n, line


def labels_in(span):
    """Labels a span cites, ranges expanded, only where they look like equation labels."""
    out = set()
    for m in RANGE.finditer(span):
        a, b = int(m.group(2)), int(m.group(3))
        if a < b <= a + 40:
            out.update("%s%d" % (m.group(1), k) for k in range(a, b + 1))
    # "(E12)", "(S2)-(S4)", "(S14, S15)", "S1–S19", "core D2", "(E15–E16)", "(S5 transposed)"
    for m in re.finditer(r"\(([^()]{0,60})\)", span):
        inner = m.group(1)
        if re.match(r"\s*[%s]\d{1,2}\b" % PREFIXES, inner):
            out.update(x.group(0) for x in LABEL.finditer(inner))
    for m in re.finditer(r"\b(?:in|of|see|core|and|equations?)\s+([%s]\d{1,2})\b" % PREFIXES,
                         span):
        out.add(m.group(1))
    return out


PAGE_RANGE = re.compile(r"docs/math/(\w+)\.md`?[^|\n]*?\b(([%s])(\d{1,2})\s*[-–]\s*\3(\d{1,2}))"
                        % PREFIXES)

for f, text in sorted(TEXT.items()):
    for n, span in cited_spans(f, text):
        for label in sorted(labels_in(span)):
            if label not in page_of:
                problem(f, n, "cited label (%s) is not defined in docs/math" % label)
                continue
            page = page_of[label]
            if "/splat/" in "/" + f and page.endswith("skin.md"):
                problem(f, n, "splat file cites skin's label (%s) (splat labels are R)" % label)
            if "/skin/" in "/" + f and page.endswith("splat.md"):
                problem(f, n, "skin file cites splat's label (%s)" % label)
        if f == "README.md":
            for m in PAGE_RANGE.finditer(span):
                page, prefix = "docs/math/%s.md" % m.group(1), m.group(3)
                nums = sorted(int(l[1:]) for l, p in page_of.items()
                              if p == page and l[0] == prefix)
                if nums and (int(m.group(4)), int(m.group(5))) != (nums[0], nums[-1]):
                    problem(f, n, "range %s does not match %s, which has %s%d–%s%d"
                            % (m.group(2), page, prefix, nums[0], prefix, nums[-1]))

for p in problems:
    print(p)
sys.exit(1 if problems else 0)
