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
    labels exactly, one range for each prefix the page defines; files under splat/ must not cite skin's S labels and files under skin/ must
    not cite splat's R labels.

(e) docs/quickstart.md shows every file of examples/quickstart/ byte for byte: a line
    "<!-- file: examples/quickstart/X -->" is followed by a fenced block whose content is
    exactly that file (the programs are built and run by ctest, tests/CMakeLists.txt); every
    file there is shown once, and the command blocks that scripts/check_packaging.sh runs
    ("<!-- run: ... -->" in docs/quickstart.md and README.md) exist.
    `scripts/check_docs.py --sync-quickstart` rewrites the page's blocks from the files.

Prints one line per problem, "path:line: message", and exits 1 if there are any.
"""

import os
import re
import subprocess
import sys

SYNC = "--sync-quickstart" in sys.argv[1:]
ARGS = [a for a in sys.argv[1:] if a != "--sync-quickstart"]
ROOT = os.path.abspath(ARGS[0] if ARGS else
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
            # Every range after a page's name on the line ("docs/math/core.md`, C1–C9, Q1–Q5,
            # D1–D6") must span that page's labels of its prefix exactly, and every prefix the
            # page defines must have its range there.
            for m in re.finditer(r"docs/math/(\w+)\.md`?([^|\n]*)", span):
                page = "docs/math/%s.md" % m.group(1)
                prefixes = sorted({l[0] for l, p in page_of.items() if p == page})
                ranges = list(re.finditer(r"\b([%s])(\d{1,2})\s*[-–]\s*\1(\d{1,2})\b" % PREFIXES,
                                          m.group(2).split("docs/math/")[0]))
                if not ranges:
                    continue
                seen = set()
                for r in ranges:
                    prefix = r.group(1)
                    seen.add(prefix)
                    nums = sorted(int(l[1:]) for l, p in page_of.items()
                                  if p == page and l[0] == prefix)
                    if not nums:
                        problem(f, n, "range %s: %s defines no %s labels" % (r.group(0), page, prefix))
                    elif (int(r.group(2)), int(r.group(3))) != (nums[0], nums[-1]):
                        problem(f, n, "range %s does not match %s, which has %s%d–%s%d"
                                % (r.group(0), page, prefix, nums[0], prefix, nums[-1]))
                for prefix in prefixes:
                    if prefix not in seen:
                        problem(f, n, "%s defines %s labels; the README gives no range for them"
                                % (page, prefix))

# ---------------------------------------------------------------------------------------------
# (e) the quick-start page shows the quick-start files byte for byte
QS_PAGE, QS_DIR = "docs/quickstart.md", "examples/quickstart/"
FILE_MARK = re.compile(r"^<!-- file: (\S+) -->$")
RUN_MARKS = {QS_PAGE: ["<!-- run: find_package -->"],
             "README.md": ["<!-- run: copied headers -->"]}


def quickstart_blocks(text):
    """(marker line index, path, first content line index, closing fence index) per marker."""
    lines = text.split("\n")
    out = []
    for n, line in enumerate(lines):
        m = FILE_MARK.match(line)
        if not m:
            continue
        if n + 1 >= len(lines) or not lines[n + 1].startswith("```"):
            out.append((n, m.group(1), None, None))
            continue
        end = n + 2
        while end < len(lines) and lines[end] != "```":
            end += 1
        out.append((n, m.group(1), n + 2, end if end < len(lines) else None))
    return lines, out


qs_text = read_text(QS_PAGE)
if qs_text is None:
    problem(QS_PAGE, 1, "missing: the quick-start page")
else:
    lines, blocks = quickstart_blocks(qs_text)
    shown = {}
    for n, path, first, end in blocks:
        if first is None or end is None:
            problem(QS_PAGE, n + 1, "%s: the marker must be followed by a closed ``` block" % path)
            continue
        if path in shown:
            problem(QS_PAGE, n + 1, "%s shown twice (first at line %d)" % (path, shown[path]))
        shown[path] = n + 1
        content = read_text(path)
        if content is None:
            problem(QS_PAGE, n + 1, "%s: no such file" % path)
            continue
        block = "\n".join(lines[first:end]) + "\n"
        if block != content:
            if SYNC:
                continue  # rewritten below
            a, b = block.split("\n"), content.split("\n")
            k = next((i for i in range(min(len(a), len(b))) if a[i] != b[i]), min(len(a), len(b)))
            problem(QS_PAGE, first + 1 + k,
                    "block differs from %s at its line %d (run scripts/check_docs.py "
                    "--sync-quickstart)" % (path, k + 1))
    if SYNC:
        # Replace each block with its file, last block first (earlier indices stay valid).
        new = qs_text
        for _ in range(2):
            lines2, blocks2 = quickstart_blocks(new)
            changed = False
            for n, path, first, end in reversed(blocks2):
                content = read_text(path)
                if first is None or end is None or content is None:
                    continue
                want = content[:-1].split("\n") if content.endswith("\n") else content.split("\n")
                if lines2[first:end] != want:
                    lines2[first:end] = want
                    changed = True
            new = "\n".join(lines2)
            if not changed:
                break
        with open(os.path.join(ROOT, QS_PAGE), "w", encoding="utf-8") as f:
            f.write(new)
        print("synced %s from %s*" % (QS_PAGE, QS_DIR))
    on_disk = sorted(f for f in FILES if f.startswith(QS_DIR))
    for f in on_disk:
        if f not in shown:
            problem(QS_PAGE, 1, "%s is not shown in the page (add a '<!-- file: %s -->' block)"
                    % (f, f))
for page, marks in RUN_MARKS.items():
    text = read_text(page) or ""
    for mark in marks:
        if mark not in text.split("\n"):
            problem(page, 1, "missing the command block '%s' that scripts/check_packaging.sh runs"
                    % mark)

for p in problems:
    print(p)
sys.exit(1 if problems else 0)
