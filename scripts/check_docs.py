#!/usr/bin/env python3
"""Checks that the documentation's references resolve inside the repository, and that what it says
about commands, scripts and devices is what the code does.

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
    Excerpts: in README.md and docs/, a line "<!-- excerpt: PATH -->" is followed by a fenced
    block whose lines are PATH's own, in order; a line "// ..." or "# ..." marks lines left
    out, and each run between them is consecutive lines of PATH.

(f) every command shown in README.md, docs/*.md and bench/README.md (lines of ```sh/```bash
    blocks, command-like lines of plain ``` blocks, and inline `code` that starts with scripts/,
    build/, python3, PYTHONPATH=, cmake ...) names things that exist: the script or program; each
    --flag given to a project script appears in that script's source (its argument parser or
    usage), and flags passed through to the trainer (scripts/example.sh, and after `--` for
    ladder.sh / data_ladder.sh) or to a benchmark in that program's sources; cmake's -S folders,
    --target names (targets the CMakeLists define) and -D SMG_* options; every repository path
    exists, or lies in a build folder that a script (or an earlier cmake -B / --out on the same
    page) creates, naming a program that the build defines there (build/release/examples/
    smg_trainer, build/release/bench/bench_core, ...).
(g) generated text is current: README.md's block between "<!-- smg:highlights begin -->" and
    "<!-- smg:highlights end -->" equals `bench/report.py --highlights bench/results`, and
    docs/performance.md equals `bench/report.py bench/results` (fix: `bench/report.py --readme
    README.md`, `bench/report.py bench/results > docs/performance.md`).

(h) flag values in those commands are ones the program accepts, read from its own `--help` in
    build/release/examples (skipped, with one note on stderr, for a program not built there; CI
    builds them in stage 1): smg_trainer's and scene_preview's choices ("a | b | c") and ranges
    ("in [lo, hi]"), also for flags handed on by scripts/example.sh, ladder.sh and data_ladder.sh
    (after `--`); for `smg_cli SUBCOMMAND`, every flag must be one of that subcommand's. Inline
    `smg_trainer --...`, `scene_preview --...` and `smg_cli SUB ...` in prose count as commands.
(i) every script a page names (README.md, docs/**, bench/README.md) that has a #! line, or that a
    command runs directly, is executable in git (mode 100755), and one run directly has a #! line.
(j) README.md is at most 12 000 bytes.
(k) smg_torch's devices: the operators with CUDA code are read from examples/torch/smg_torch_*.cpp
    (an m.def whose implementation calls cuda_ops()); each operator's docstring in
    smg_torch/__init__.py has exactly the line "Devices: CPU and CUDA tensors." or "Devices: CPU
    tensors only (a CUDA tensor raises NotImplementedError)." accordingly; every list of operators
    said to take CUDA tensors ("CUDA tensors for a, b and c", "a, b and c also take CUDA tensors")
    or to raise NotImplementedError on them, in the module, its comments, the extension's m.doc
    and the pages, equals the sources' set; no CUDA operator is marked "(CPU)".
(l) no command says `python` (bookworm has only python3), and `pip install` always carries
    --no-build-isolation (smg_torch builds against the torch already installed).
(m) every regulariser term has its pieces (docs/contributing.md section 3).
(n) in docs/ and bench/notes/, a markdown table with a number in a cell lies between a
    generator's markers ("<!-- ladder:X -->" ... "<!-- /ladder:X -->", "<!-- terms:begin -->" ...
    "<!-- terms:end -->"), or the nearest non-blank line above it is "<!-- not generated: WHY -->".
    docs/performance.md is generated as a whole ((g)); its hand tables are its notes'.
(f) also: a page that builds some targets into a folder it configures and then runs
    `ctest --test-dir` there with -R must build every program whose test -R selects.
(o) drift between statements: a range right after the math pages it covers ("`docs/math/energy.md`
    and `docs/math/terms/`, E1–E25") that starts at their first label must end at their last; no
    sentence in README.md, docs/ or bench/notes/ says the fused CUDA step has not run on a GPU (or
    is not measured) while bench/results/gpu/ holds a run of it; a figure stated on several pages
    (scripts/test.sh's duration in README.md and docs/contributing.md) is the same on each.

Prints one line per problem, "path:line: message", and exits 1 if there are any.
"""

import os
import re
import subprocess
import sys

if "-h" in sys.argv[1:] or "--help" in sys.argv[1:]:
    print(__doc__.strip())
    sys.exit(0)
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
# docs/math/terms/<term>.md: the equations of a regulariser term added after the paper's (its own
# page, so that a new term edits no existing page; section (m)).
MATH = sorted(f for f in TEXT if re.match(r"docs/math/(terms/)?[^/]+\.md$", f))

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

# Excerpts: "<!-- excerpt: PATH -->" in README.md or a page of docs/ is followed by a fenced
# block whose lines are PATH's, in order. A line "// ..." or "# ..." (any indentation) stands for
# lines left out; each run of lines between them is consecutive lines of PATH, and the runs come
# in the file's order without overlapping.
EXCERPT_MARK = re.compile(r"^<!-- excerpt: (\S+) -->$")
ELISION = re.compile(r"^\s*(//|#) \.\.\.\s*$")


def excerpt_problem(block, source):
    """None if BLOCK (a list of lines) is an excerpt of SOURCE's lines, else (index, message)."""
    src = source.split("\n")
    runs, run, start = [], [], 0
    for k, line in enumerate(block + ["// ..."]):
        if ELISION.match(line):
            if run:
                runs.append((start, run))
            run, start = [], k + 1
        else:
            run.append(line)
    at = 0
    for start, run in runs:
        hit = next((i for i in range(at, len(src) - len(run) + 1) if src[i:i + len(run)] == run), None)
        if hit is None:
            # Name the first line that does not continue the run's longest match from `at` on.
            best = 0
            for i in range(at, len(src)):
                j = 0
                while j < len(run) and i + j < len(src) and src[i + j] == run[j]:
                    j += 1
                best = max(best, j)
            return start + best, "not the file's next line here"
        at = hit + len(run)
    return None


for f in doc_md:
    lines = TEXT[f].split("\n")
    for n, line in enumerate(lines):
        m = EXCERPT_MARK.match(line)
        if not m:
            continue
        if n + 1 >= len(lines) or not lines[n + 1].startswith("```"):
            problem(f, n + 1, "%s: the excerpt marker must be followed by a ``` block" % m.group(1))
            continue
        end = n + 2
        while end < len(lines) and lines[end] != "```":
            end += 1
        source = read_text(m.group(1))
        if end >= len(lines):
            problem(f, n + 1, "%s: the excerpt's block is not closed" % m.group(1))
        elif source is None:
            problem(f, n + 1, "%s: no such file" % m.group(1))
        else:
            bad = excerpt_problem(lines[n + 2:end], source)
            if bad:
                problem(f, n + 3 + bad[0], "excerpt of %s: %s (the block's lines must be the file's, "
                        "in order; '// ...' marks lines left out)" % (m.group(1), bad[1]))

# ---------------------------------------------------------------------------------------------
# (f) commands in the docs name scripts, flags, targets and paths that exist
import shlex  # noqa: E402

CMD_PAGES = sorted(f for f in TEXT if f.endswith(".md") and
                   (f == "README.md" or f == "bench/README.md" or re.match(r"docs/[^/]+\.md$", f)))
TOP = sorted({f.split("/", 1)[0] for f in FILES})
SCRIPT_EXT = (".sh", ".py")
CODE_OF = {}


def sources_under(*prefixes):
    """The concatenated text of the tracked files under the given folders (or the files)."""
    key = prefixes
    if key not in CODE_OF:
        CODE_OF[key] = "\n".join(t for f, t in TEXT.items() if f.startswith(prefixes))
    return CODE_OF[key]


TRAINER_SRC = ("examples/trainer/", "examples/common/")
PROGRAM_SRC = {"smg_trainer": TRAINER_SRC, "scene_preview": TRAINER_SRC,
               "smg_cli": ("examples/cli/", "examples/common/"), "core_tour": ("examples/core_tour.cpp",)}
# Scripts that hand flags on: (what gets them, all flags or only those after `--`).
PASS_ON = {"scripts/example.sh": (TRAINER_SRC, False), "scripts/ladder.sh": (TRAINER_SRC, True),
           "scripts/data_ladder.sh": (TRAINER_SRC, True), "scripts/bench.sh": (("bench/",), True)}
SCRIPT_TEXT = "\n".join(TEXT.get(f, "") for f in FILES
                        if f.startswith("scripts/") or f == ".ci/run")
# Build folders the scripts create (build/release, build/asan, build/lint, build/bench-results, ...)
# and the folders they create inside a build folder ($build/bench-smoke, $build/python).
SCRIPT_BUILD_DIRS = {"build/" + m for m in re.findall(r"(?<![\w$}/.])build/([\w.-]+)", SCRIPT_TEXT)}
IN_BUILD = set(re.findall(r"\$\{?build\}?/([\w.-]+)", SCRIPT_TEXT))
# Top-level build folders whose remainder must name a program of the build.
PROJECT_BUILDS = {"build/release", "build/asan", "build/lint"}


def cmake_texts():
    return {f: TEXT[f] for f in TEXT if os.path.basename(f) == "CMakeLists.txt"}


def exe_patterns(folder):
    """Regular expressions of the programs a CMakeLists.txt folder defines (add_executable)."""
    text = TEXT.get((folder + "/" if folder else "") + "CMakeLists.txt", "")
    pats = []
    for m in re.finditer(r"add_executable\(\s*([^\s)]+)", text):
        pats.append("^" + re.sub(r"\\\$\\\{\w+\\\}", ".+", re.escape(m.group(1))) + "$")
    return pats


def targets():
    names = set()
    for f, text in cmake_texts().items():
        for m in re.finditer(r"(?:add_executable|add_library|pybind11_add_module|add_custom_target)"
                             r"\(\s*([\w:]+)", text):
            names.add(m.group(1))
    names |= {"test_" + d.split("/")[1] for d in FILES if re.match(r"tests/[^/]+/.+\.cpp$", d)
              and d.split("/")[1] not in ("support", "consumer", "probes")}
    names |= {re.sub(r"^bench/(bench_\w+)\.cpp$", r"\1", f) for f in FILES
              if re.match(r"bench/bench_\w+\.cpp$", f)}
    names |= {"quickstart_" + os.path.basename(f)[:-4] for f in FILES
              if re.match(r"examples/quickstart/\w+\.cpp$", f)}
    return names


TARGETS = targets()
# ctest's test names: add_test(NAME x) and the quick-start programs' tests (tests/CMakeLists.txt).
TEST_NAMES = set(re.findall(r"add_test\(\s*NAME\s+(\w+)(?=[\s)])", "\n".join(cmake_texts().values()))) | \
    {"quickstart_" + os.path.basename(f)[:-4] for f in FILES if re.match(r"examples/quickstart/\w+\.cpp$", f)}
SMG_OPTIONS = set(re.findall(r"\b(SMG_\w+)\b", "\n".join(cmake_texts().values())))


def program_ok(rel, source):
    """Is build-folder path `rel` (e.g. examples/smg_trainer) something the build of `source`
    defines? None when it is, else the reason."""
    parts = rel.split("/")
    if not rel or parts[0] in IN_BUILD - {"examples", "bench", "tests"}:
        return None
    folder = "/".join(([source] if source != "." else []) + parts[:-1])
    name = parts[-1]
    if not os.path.isdir(os.path.join(ROOT, folder)):
        if len(parts) == 1 and os.path.isdir(os.path.join(ROOT, source, name)):
            return None  # the binary folder of a source folder (build/release/tests)
        return "no source folder %s for it" % folder
    if len(parts) == 1 and os.path.isdir(os.path.join(ROOT, folder, name)):
        return None
    if folder == "bench" and not os.path.exists(os.path.join(ROOT, "bench", name + ".cpp")):
        return "no bench/%s.cpp" % name
    if folder == "tests" and not (name.startswith("test_") and
                                  os.path.isdir(os.path.join(ROOT, "tests", name[5:]))):
        return "no tests/%s folder" % name[5:]
    if folder == "examples/quickstart" and not os.path.exists(
            os.path.join(ROOT, folder, name.replace("quickstart_", "", 1) + ".cpp")):
        return "no %s/%s.cpp" % (folder, name.replace("quickstart_", "", 1))
    if not any(re.match(p, name) for p in exe_patterns(folder)):
        return "%s/CMakeLists.txt defines no program %s" % (folder, name)
    return None


def path_problem(tok, cwd, made):
    """None if the repository path `tok` (relative to `cwd`) is fine, else why not."""
    rel = os.path.normpath(os.path.join(cwd, tok))
    if rel.startswith(".."):
        return None  # outside the repository (a sibling project of the README's examples)
    if rel == "build" or not rel.startswith("build/"):
        return None if os.path.exists(os.path.join(ROOT, rel)) else "no such file or folder"
    parts = rel.split("/")
    top = "/".join(parts[:2])
    if top in made:
        source = made[top]
    elif top in SCRIPT_BUILD_DIRS:
        source = "." if top in PROJECT_BUILDS else None
    else:
        return ("no script builds into %s (the build folder is build/release: scripts/test.sh, "
                "scripts/example.sh, scripts/bench.sh)" % top)
    if source is None or len(parts) == 2:
        return None
    return program_ok("/".join(parts[2:]), source)


def looks_like_path(tok):
    if not tok or tok.startswith(("/", "$", "~", "-")) or re.search(r"[<>*{}…|]|\.\.\.", tok):
        return False
    first = tok.split("/", 1)[0]
    return "/" in tok and (first in TOP or first == "build") or tok in TOP and "." in tok


def flag_problem(flag, source_text, program):
    name = flag.split("=", 1)[0]
    if re.search(re.escape(name) + r"(?![\w-])", source_text):
        return None
    if program == "bench" and name.startswith("--benchmark_"):
        return None
    bare = name.lstrip("-")
    if program in ("trainer", "bench", "program") and re.search(r'"%s"' % re.escape(bare), source_text):
        return None
    return "flag %s is not in %s" % (name, {"trainer": "the trainer's sources (examples/trainer)",
                                             "bench": "the benchmarks' sources (bench/)"}.get(program, program))


def split_commands(line):
    try:
        lex = shlex.shlex(line, posix=True, punctuation_chars="|&;")
        lex.whitespace_split = True
        lex.commenters = "#"
        toks = list(lex)
    except ValueError:
        toks = line.split()
    cmd = []
    for t in toks:
        if t and set(t) <= set("|&;"):
            if cmd:
                yield cmd
            cmd = []
        else:
            cmd.append(t)
    if cmd:
        yield cmd


OUT_FLAGS = ("--out", "-B", "--prefix", "--json", "-o", "--export-case", "--export-dycheck", "--doc")


# (h) flag values against the program's own --help: the choices
# ("a | b | c") and ranges ("in [lo, hi]") it prints, and for smg_cli each subcommand's flags.
HELP_BUILD = os.path.join(ROOT, "build", "release", "examples")
HELP_CACHE = {}
HELP_MISSING = set()


def strip_parentheticals(text):
    """Removes (...) groups that are not a list of choices, innermost first."""
    while True:
        new = re.sub(r"\(([^()]*)\)", lambda m: m.group(0).replace("(", "\x00").replace(")", "\x01")
                     if " | " in m.group(1) or "in [" in m.group(1) else "", text)
        if new == text:
            return new.replace("\x00", "(").replace("\x01", ")")
        text = new


def program_help(program):
    """{flag: (takes a value, choices or None, (lo, hi) or None)} from `program --help`
    ("smg_cli graph": the subcommand's), or None when the program is not built."""
    if program in HELP_CACHE:
        return HELP_CACHE[program]
    words = program.split()
    exe = os.path.join(HELP_BUILD, words[0])
    flags = None
    if os.access(exe, os.X_OK):
        try:
            out = subprocess.run([exe] + words[1:] + ["--help"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 timeout=20).stdout.decode("utf-8", "replace")
        except (OSError, subprocess.TimeoutExpired):
            out = ""
        flags = {}
        lines = out.split("\n")
        for i, line in enumerate(lines):
            m = re.match(r"^  (--[\w-]+)(?: (\S+))?\s*$", line)
            if not m:
                continue
            body = []
            for l in lines[i + 1:]:
                if not l.startswith("      "):
                    break
                body.append(l.strip())
            help_text = " ".join(body)
            help_text = strip_parentheticals(help_text)
            choices = rng = None
            c = re.search(r"((?:[\w.+-]+ \| )+[\w.+-]+)", help_text)
            if c:
                choices = set(c.group(1).split(" | "))
            r = re.search(r"in \[([-\d.e+]+), ([-\d.e+]+)\]", help_text)
            if r:
                rng = (float(r.group(1)), float(r.group(2)))
            flags[m.group(1)] = (m.group(2) is not None, choices, rng)
        if not flags:
            flags = None
    else:
        HELP_MISSING.add(words[0])
    HELP_CACHE[program] = flags
    return flags


def is_placeholder(value):
    return (not value or re.search(r"[$<>{}*…|]|\.\.\.", value) is not None
            or re.fullmatch(r"[A-Z][A-Z0-9_./-]*", value) is not None)


def check_flag_values(f, n, program, args):
    """Each --flag among args is one `program --help` lists, with a value among its choices or in
    its range (values that are placeholders, SCENE or $x, are skipped)."""
    spec = program_help(program)
    if spec is None:
        return
    i = 0
    while i < len(args):
        a = args[i]
        i += 1
        if not a.startswith("--") or a == "--":
            continue
        name, eq, value = a.partition("=")
        if name not in spec:
            if not program.startswith("smg_cli") or name in ("--help",):
                continue  # the trainer's flags are checked against its sources above
            problem(f, n, "%s: flag %s is not in `%s --help`" % (program, name, program))
            continue
        takes, choices, rng = spec[name]
        if not takes:
            continue
        if not eq:
            if i >= len(args) or args[i].startswith("-"):
                continue
            value = args[i]
            i += 1
        if is_placeholder(value):
            continue
        if choices and value not in choices:
            problem(f, n, "%s %s %s: not one of %s (`%s --help`)" % (program, name, value,
                                                                     " | ".join(sorted(choices)), program))
        elif rng:
            try:
                v = float(value)
            except ValueError:
                problem(f, n, "%s %s %s: not a number (`%s --help`)" % (program, name, value, program))
                continue
            if not rng[0] <= v <= rng[1]:
                problem(f, n, "%s %s %s: outside [%g, %g] (`%s --help`)" % (program, name, value, rng[0], rng[1],
                                                                            program))


def check_command(f, n, toks, state):
    """One command (a token list); state: cwd and the build folders made on this page."""
    toks = [t.strip("[]") for t in toks]
    toks = [t for t in toks if t]
    env = []
    while toks and re.match(r"^[A-Za-z_]\w*=", toks[0]):
        env.append(toks.pop(0))
    while toks and toks[0] in ("time", "sudo", "exec", "env"):
        toks.pop(0)
    if not toks:
        return
    prog, args = toks[0], toks[1:]
    if prog in ("smg_trainer", "scene_preview", "smg_cli"):
        prog = "build/release/examples/" + prog  # the program as a page names it in prose
    for e in env:
        for v in e.split("=", 1)[1].split(":"):
            if looks_like_path(v):
                why = path_problem(v, state["cwd"], state["made"])
                if why:
                    problem(f, n, "%s: %s" % (v, why))
    checked_paths = []
    flags_to = []  # (flag, source text, program kind)
    if prog == "cd":
        if args and looks_like_path(args[0]):
            why = path_problem(args[0], state["cwd"], state["made"])
            if why:
                problem(f, n, "cd %s: %s" % (args[0], why))
            state["cwd"] = os.path.normpath(os.path.join(state["cwd"], args[0]))
        return
    if prog in ("python3", "/usr/bin/python3", "python"):
        if "-c" in args:
            return
        if "-m" in args:
            for a in args[args.index("-m") + 2:]:
                if looks_like_path(a):
                    why = path_problem(a, state["cwd"], state["made"])
                    if why:
                        problem(f, n, "%s: %s" % (a, why))
            return
        else:
            rest = [a for a in args if not a.startswith("-")]
            if not rest:
                return
            prog, args = rest[0], args[args.index(rest[0]) + 1:]
    if prog == "cmake":
        i = 0
        source = None
        while i < len(args):
            a = args[i]
            val = args[i + 1] if i + 1 < len(args) else ""
            if a == "-S":
                source = os.path.normpath(os.path.join(state["cwd"], val))
                if (val == "." or looks_like_path(val + "/")) and \
                        not os.path.isfile(os.path.join(ROOT, source, "CMakeLists.txt")):
                    problem(f, n, "cmake -S %s: no CMakeLists.txt there" % val)
                i += 2
                continue
            if a == "-B":
                state["made"]["/".join(os.path.normpath(os.path.join(state["cwd"], val)).split("/")[:2])] = \
                    source if source else "."
                i += 2
                continue
            if a in ("--build", "--install", "--test-dir"):
                if looks_like_path(val):
                    checked_paths.append(val)
                i += 2
                continue
            if a == "--target":
                j = i + 1
                while j < len(args) and not args[j].startswith("-"):
                    if args[j] not in TARGETS:
                        problem(f, n, "cmake --target %s: no such target in the CMakeLists" % args[j])
                    j += 1
                if "--build" in args:
                    built = os.path.normpath(os.path.join(state["cwd"], args[args.index("--build") + 1]))
                    state.setdefault("built", {}).setdefault(built, set()).update(args[i + 1:j])
                i = j
                continue
            m = re.match(r"^-D(SMG_\w+)", a)
            if m and m.group(1) not in SMG_OPTIONS:
                problem(f, n, "cmake %s: no option %s in the CMakeLists" % (a, m.group(1)))
            i += 1
        for p in checked_paths:
            why = path_problem(p, state["cwd"], state["made"])
            if why:
                problem(f, n, "%s: %s" % (p, why))
        return
    if prog == "ctest":
        if "--test-dir" in args:
            checked_paths.append(args[args.index("--test-dir") + 1])
            # A page that builds only some targets into a folder it configures, then runs ctest
            # there: every test that -R selects and whose program is a target must be built
            # (tests/run_expect.cmake fails a test whose program is missing).
            tdir = os.path.normpath(os.path.join(state["cwd"], args[args.index("--test-dir") + 1]))
            built = state.get("built", {}).get(tdir)
            if built is not None and "-R" in args and args.index("-R") + 1 < len(args):
                pat = args[args.index("-R") + 1].strip("'\"")
                missing = sorted(t for t in TEST_NAMES & TARGETS if re.search(pat, t) and t not in built)
                if missing:
                    problem(f, n, "ctest -R %s runs %s, which this page's cmake --build %s --target "
                                  "does not build" % (pat, ", ".join(missing), tdir))
        args = []
    elif looks_like_path(prog):
        why = path_problem(prog, state["cwd"], state["made"])
        rel = os.path.normpath(os.path.join(state["cwd"], prog))
        if why:
            problem(f, n, "%s: %s" % (prog, why))
        elif not rel.startswith("build/") and rel.endswith(SCRIPT_EXT + ("run",)):
            text = TEXT.get(rel, "")
            dest = PASS_ON.get(rel)
            if dest and dest[0] == TRAINER_SRC:
                check_flag_values(f, n, "smg_trainer", args[args.index("--") + 1:] if dest[1] and "--" in args
                                  else ([] if dest[1] else args))
            after = False
            for a in args:
                if a == "--":
                    after = True
                    continue
                if not a.startswith("--"):
                    continue
                if dest and (after or not dest[1]):
                    kind = "bench" if dest[0] == ("bench/",) else "trainer"
                    flags_to.append((a, sources_under(*dest[0]), kind))
                elif not after:
                    flags_to.append((a, text, rel))
        elif rel.startswith("build/"):
            name = os.path.basename(rel)
            src = PROGRAM_SRC.get(name)
            if name in ("smg_trainer", "scene_preview"):
                check_flag_values(f, n, name, args)
            elif name == "smg_cli" and args and re.fullmatch(r"[a-z]+", args[0]):
                check_flag_values(f, n, "smg_cli " + args[0], args[1:])
            kind = "trainer" if src == TRAINER_SRC else "program"
            if name.startswith("bench_"):
                src, kind = ("bench/",), "bench"
            if src:
                for a in args:
                    if a.startswith("--"):
                        flags_to.append((a, sources_under(*src), kind if kind != "program" else name))
    elif prog not in ("cp", "g++", "pip", "ls", "cat", "mkdir", "cd"):
        return
    for a in args:
        v = a.split("=", 1)[1] if a.startswith("-") and "=" in a else a
        if looks_like_path(v):
            checked_paths.append(v)
    for i, a in enumerate(args):
        if a in OUT_FLAGS and i + 1 < len(args):
            out = os.path.normpath(os.path.join(state["cwd"], args[i + 1]))
            if out.startswith("build/"):
                state["made"].setdefault("/".join(out.split("/")[:2]), None)
            if args[i + 1] in checked_paths and not os.path.exists(os.path.join(ROOT, out)):
                checked_paths.remove(args[i + 1])  # an output the command creates
    for p in checked_paths:
        why = path_problem(p, state["cwd"], state["made"])
        if why:
            problem(f, n, "%s: %s" % (p, why))
    for flag, text, kind in flags_to:
        why = flag_problem(flag, text, kind)
        if why:
            problem(f, n, why)


CMD_START = re.compile(r"^(?:[A-Za-z_]\w*=\S*\s+)*(?:time\s+)?(?:scripts/|build/|\.ci/|bench/\S+\.py|"
                       r"examples/\S+\.py|python3?\s|/usr/bin/python3\s|cmake\s|ctest\s|cd\s|"
                       r"smg_trainer\s+-|scene_preview\s+-|smg_cli\s+[a-z]+\s)")


def doc_commands(text):
    """(line number, command line) of a page: shell blocks, command-like lines of plain blocks,
    inline code that starts like a command."""
    lines = text.split("\n")
    fenced, lang = False, ""
    n = 0
    while n < len(lines):
        line = lines[n]
        m = FENCE.match(line)
        if m:
            fenced = not fenced
            lang = line.strip()[3:].strip().lower() if fenced else ""
            n += 1
            continue
        if fenced:
            start = n
            while line.endswith("\\") and n + 1 < len(lines):
                n += 1
                line = line[:-1] + " " + lines[n].strip()
            s = line.strip()
            if lang in ("sh", "bash", "console", "shell"):
                if s and not s.startswith("#"):
                    yield start + 1, s
            elif lang == "" and CMD_START.match(s) and not s.split()[0].endswith("/"):
                yield start + 1, s
        n += 1
    # Inline code, which may wrap onto the next line: over the text outside fenced blocks.
    prose, fenced = [], False
    for line in lines:
        if FENCE.match(line):
            fenced = not fenced
            prose.append("")
        else:
            prose.append("" if fenced else line)
    prose = "\n".join(prose)
    for m in re.finditer(r"`([^`]+)`", prose):
        span = " ".join(m.group(1).split())
        if span and CMD_START.match(span) and not span.split()[0].endswith("/") \
                and not re.search(r"[<>*{}…]|\.\.\.", span.split()[0]):
            yield prose.count("\n", 0, m.start()) + 1, span


for f in CMD_PAGES:
    state = {"made": {}}
    for n, line in doc_commands(TEXT[f]):
        state["cwd"] = "."
        for cmd in split_commands(line):
            check_command(f, n, cmd, state)

# ---------------------------------------------------------------------------------------------
# (i) scripts the docs name are executable
DOC_PAGES = sorted(f for f in TEXT if f.endswith(".md") and (f in ("README.md", "bench/README.md")
                                                             or f.startswith("docs/")))


def git_modes():
    try:
        out = subprocess.run(["git", "-C", ROOT, "ls-files", "-s", "-z"], check=True,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL).stdout.decode("utf-8", "replace")
        return {e.split("\t", 1)[1]: e.split()[0] for e in out.split("\0") if "\t" in e}
    except (OSError, subprocess.CalledProcessError):
        return {}


MODES = git_modes()
SCRIPT_NAME = re.compile(r"(?<![\w/.-])((?:scripts|bench|examples|tests|\.ci)/[\w./-]*\.(?:sh|py)|\.ci/run)\b")
RUN_AS_COMMAND = set()
for f in CMD_PAGES:
    for n, line in doc_commands(TEXT[f]):
        for cmd in split_commands(line):
            cmd = [t for t in cmd if not re.match(r"^[A-Za-z_]\w*=", t)]
            if cmd and SCRIPT_NAME.fullmatch(cmd[0]):
                RUN_AS_COMMAND.add((cmd[0], f, n))
named = {}
for f in DOC_PAGES:
    for m in SCRIPT_NAME.finditer(TEXT[f]):
        named.setdefault(m.group(1), (f, TEXT[f].count("\n", 0, m.start()) + 1))
for script, f, n in sorted(RUN_AS_COMMAND):
    named.setdefault(script, (f, n))
for script, (f, n) in sorted(named.items()):
    text = TEXT.get(script)
    if text is None:
        continue  # a missing file is (f)'s problem
    as_command = any(s == script for s, _, _ in RUN_AS_COMMAND)
    shebang = text.startswith("#!")
    mode = MODES.get(script) or ("100755" if os.access(os.path.join(ROOT, script), os.X_OK) else "100644")
    if (shebang or as_command) and mode != "100755":
        problem(f, n, "%s is named here but is not executable (mode %s; fix: git update-index --chmod=+x %s)"
                % (script, mode, script))
    if as_command and not shebang:
        problem(f, n, "%s is run as a command here but has no #! line" % script)

# ---------------------------------------------------------------------------------------------
# (j) the README's size budget
README_BUDGET = 12000
if "README.md" in TEXT and len(TEXT["README.md"].encode("utf-8")) > README_BUDGET:
    problem("README.md", 1, "%d bytes, over the budget of %d: move detail to docs/"
            % (len(TEXT["README.md"].encode("utf-8")), README_BUDGET))

# ---------------------------------------------------------------------------------------------
# (k) the devices smg_torch's operators take, as its sources say, in its docstrings and the docs
TORCH_CPP = {f: t for f, t in TEXT.items() if re.match(r"examples/torch/smg_torch_\w+\.cpp$", f)}
TORCH_INIT = "examples/torch/smg_torch/__init__.py"


def torch_cuda_operators():
    """(every operator of smg_torch._C, the ones with CUDA code): an m.def("name", ...) whose body
    or implementation function calls cuda_ops(); dqb_forward/dqb_backward are dqb, render_* render."""
    every, cuda = set(), set()
    for text in TORCH_CPP.values():
        with_cuda = set()
        for m in re.finditer(r"\n(?:[\w:<>,]+\s+)+(\w+)\((?:[^()]|\([^()]*\))*\)\s*\{", text):
            end = text.find("\n}", m.end())
            if "cuda_ops()" in text[m.end():end]:
                with_cuda.add(m.group(1))
        defs = list(re.finditer(r'm\.def\(\s*"(\w+)"', text))
        for k, m in enumerate(defs):
            name = m.group(1)
            if name.startswith("_") or name in ("set_memory_limit", "memory_limit"):
                continue
            body = text[m.end():defs[k + 1].start() if k + 1 < len(defs) else len(text)]
            op = re.sub(r"_(forward|backward)$", "", name)
            every.add(op)
            if any(re.search(r"\b%s\b" % re.escape(fn), body) for fn in with_cuda) or "cuda_ops()" in body:
                cuda.add(op)
    return every, cuda


if TORCH_CPP and TORCH_INIT in TEXT:
    OPS, CUDA_OPS = torch_cuda_operators()
    init = TEXT[TORCH_INIT]
    want = {True: "Devices: CPU and CUDA tensors.",
            False: "Devices: CPU tensors only (a CUDA tensor raises NotImplementedError)."}
    for op in sorted(OPS):
        m = re.search(r'\ndef %s\((?:.|\n)*?\)(?:\s*->[^:\n]*)?:\n\s*"""((?:.|\n)*?)"""' % re.escape(op), init)
        if not m:
            problem(TORCH_INIT, 1, "no docstring for smg_torch.%s (the _C module defines it)" % op)
            continue
        line = init.count("\n", 0, m.start(1)) + 1
        devices = re.findall(r"Devices: [^\n]*", m.group(1))
        if devices != [want[op in CUDA_OPS]]:
            problem(TORCH_INIT, line, "smg_torch.%s's docstring must say \"%s\" (its C++ %s CUDA code), not %s"
                    % (op, want[op in CUDA_OPS], "has" if op in CUDA_OPS else "has no", devices or "nothing"))
    # Lists of operators said to take CUDA tensors, or to raise NotImplementedError on them, in the
    # module's docstrings and comments, the extension's m.doc and the docs: each equals the sources' set.
    names = "|".join(sorted(OPS, key=len, reverse=True))
    op_list = r"((?:`?(?:%s)`?(?:,\s+|\s+and\s+|\s+or\s+|,\s+and\s+))+`?(?:%s)`?)" % (names, names)
    places = [TORCH_INIT, "examples/torch/smg_torch_ext.cpp"] + DOC_PAGES
    for f in places:
        text = TEXT.get(f, "")
        flat = re.sub(r"\s+", " ", re.sub(r"\n\s*(?:#:?|//)\s*", " ", text))
        for m in re.finditer(r"(?:CUDA tensors (?:for|to) |CUDA operators? (?:for )?)" + op_list, flat):
            got = set(re.findall(r"\b(%s)\b" % names, m.group(1)))
            if got != CUDA_OPS:
                problem(f, 1, "lists %s as the operators on CUDA tensors; the sources say %s"
                        % (", ".join(sorted(got)), ", ".join(sorted(CUDA_OPS))))
        for m in re.finditer(op_list + r"(?: also)? (?:take|takes|run on|accept) CUDA tensors", flat):
            got = set(re.findall(r"\b(%s)\b" % names, m.group(1)))
            if got != CUDA_OPS:
                problem(f, 1, "lists %s as the operators that take CUDA tensors; the sources say %s"
                        % (", ".join(sorted(got)), ", ".join(sorted(CUDA_OPS))))
        for m in re.finditer(r"(?:\(|: )" + op_list + r"\)?[^.]{0,40}?NotImplementedError|NotImplementedError[^.]{0,60}?\(" + op_list + r"\)", flat):
            got = set(re.findall(r"\b(%s)\b" % names, m.group(1) or m.group(2)))
            if got != OPS - CUDA_OPS:
                problem(f, 1, "lists %s as the CPU-only operators; the sources say %s"
                        % (", ".join(sorted(got)), ", ".join(sorted(OPS - CUDA_OPS))))
        for m in re.finditer(r"`?(%s)`?[^.;\n]{0,60}?\((?:CPU|CPU only|CPU-only|CPU tensors)\)" % names, flat):
            if m.group(1) in CUDA_OPS:
                problem(f, 1, "marks %s as CPU-only; its C++ has CUDA code" % m.group(1))

# ---------------------------------------------------------------------------------------------
# (l) Python commands as a Debian user can run them: `python3` (bookworm has no `python`), and
# pip only with --no-build-isolation (smg_torch builds against the torch already installed)
for f in CMD_PAGES:
    for n, line in doc_commands(TEXT[f]):
        for cmd in split_commands(line):
            toks = [t for t in cmd if not re.match(r"^[A-Za-z_]\w*=", t)]
            if toks and toks[0] == "python":
                problem(f, n, "`python` is not a command on Debian bookworm: say python3")
            if toks and os.path.basename(toks[0]) in ("pip", "pip3") and "install" in toks and \
                    "--no-build-isolation" not in toks:
                problem(f, n, "pip install without --no-build-isolation (docs/torch.md, \"Building it\")")

# ---------------------------------------------------------------------------------------------
# (m) every regulariser term has its pieces (docs/contributing.md section 3): a header in
# include/smg/energy/terms/ is reached from the fused step's header (regularizers.hpp includes
# it, or the one-term operator that includes it; the umbrella energy.hpp includes
# regularizers.hpp), its term struct is on the fused step's list (term_list.hpp's SMG_REGULARIZER_TERMS, or
# the confidences' member of RegularizerTermSet), its
# header is named in docs/math/energy.md or on its own page docs/math/terms/<name>.md, and (for an energy, not the confidences) its one-term
# operator has an entry in the operator list of the cross-cutting tests.
TERMS_DIR = "include/smg/energy/terms"
umbrella = read_text("include/smg/energy.hpp") or ""
regs = read_text("include/smg/energy/regularizers.hpp") or ""
term_list_hpp = read_text("include/smg/energy/term_list.hpp") or ""
INCLUDE_RE = re.compile(r'^#include "(smg/[\w/]+\.hpp)"', re.M)
reached = set(INCLUDE_RE.findall(regs))
for inc in list(reached):
    reached |= set(INCLUDE_RE.findall(read_text("include/" + inc) or ""))
if '#include "smg/energy/regularizers.hpp"' not in umbrella:
    problem("include/smg/energy.hpp", 1, "does not include smg/energy/regularizers.hpp (the term list)")
# The list: the confidences (the member ConfidenceTerm<S, I> of RegularizerTermSet) and one line
# X(name, Options, Term, on) of SMG_REGULARIZER_TERMS per energy term.
term_set = term_list_hpp[term_list_hpp.find("#define SMG_REGULARIZER_TERMS(X)"):]
term_set = term_set[:term_set.find("\n\n")]
term_set += "".join(re.findall(r"\n  \w+Term<S, I> \w+;", term_list_hpp))
listed_terms = set(re.findall(r"^\s*X\(\w+,\s*\w+,\s*(\w+),", term_set, re.M))
listed_terms |= set(re.findall(r"\b(\w+Term)<S, I> \w+;", term_set))
operators = read_text("tests/support/operators.hpp") or ""
# The list: a std::tuple of operators, or one joined with generated variants (std::tuple_cat).
op_list = re.search(r"using Operators = (?:decltype\(std::tuple_cat\()?std::tuple<([^>]*)>", operators)
op_names = set(re.findall(r'static constexpr const char\* name = "(\w+)"', operators))
energy_md = TEXT.get("docs/math/energy.md", "")
for rel in sorted(f for f in tracked_files() if f.startswith(TERMS_DIR + "/") and f.endswith(".hpp")):
    name = os.path.basename(rel)[:-4]
    text = read_text(rel) or ""
    if "smg/energy/terms/%s.hpp" % name not in reached:
        problem("include/smg/energy/regularizers.hpp", 1,
                "reaches %s neither directly nor through a one-term operator it includes" % rel)
    structs = re.findall(r"struct (\w+Term) : [^{]*\b(?:TermDefaults|ScratchFree\w*Term)\b", text)
    if not structs:
        problem(rel, 1, "no term struct (struct FooTerm : TermDefaults or ScratchFreeTerm, energy/block.hpp's concept)")
    for st in structs:
        if st not in listed_terms:
            problem("include/smg/energy/term_list.hpp", 1,
                    "%s (%s) is on neither SMG_REGULARIZER_TERMS nor RegularizerTermSet" % (st, rel))
    own_page = "docs/math/terms/%s.md" % name
    if "terms/%s.hpp" % name not in energy_md and "terms/%s.hpp" % name not in TEXT.get(own_page, ""):
        problem("docs/math/energy.md", 1, "does not name %s (nor does %s)" % (rel, own_page))
    # The operator list names one-term operators: carap/arap for the rigid term, lrm, accel.
    wanted = {"rigid": ["carap", "arap"], "confidence": ["confidences"]}.get(name, [name])
    for op in wanted:
        if op not in op_names:
            problem("tests/support/operators.hpp", 1, "no operator '%s' for %s in the list" % (op, rel))
if op_list is None:
    problem("tests/support/operators.hpp", 1, "no `using Operators = std::tuple<...>` list")
import importlib.util  # noqa: E402

# The terms' table of docs/api.md is scripts/terms_table.py's output (generated from the code),
# and every term reaches every place the table lists.
_tspec = importlib.util.spec_from_file_location("smg_terms_table", os.path.join(ROOT, "scripts", "terms_table.py"))
terms_table = importlib.util.module_from_spec(_tspec)
try:
    _tspec.loader.exec_module(terms_table)
    api = TEXT.get("docs/api.md", "")
    tb, te = terms_table.BEGIN, terms_table.END
    if tb not in api or te not in api:
        problem("docs/api.md", 1, "no '%s' ... '%s' block (scripts/terms_table.py --write docs/api.md)" % (tb, te))
    elif api[api.index(tb) + len(tb):api.index(te)].lstrip("\n") != terms_table.table():
        problem("docs/api.md", 1, "the terms' table is out of date: run scripts/terms_table.py --write docs/api.md")
    for flag, r in terms_table.rows():
        if r is None:
            problem("include/smg/energy/term_list.hpp", 1, "the term of RegularizerTerms::%s has no header in energy/terms/" % flag)
            continue
        for col in ("options", "call", "torch", "bench", "cuda", "tests"):
            if r[col] == "—":
                problem("docs/api.md", 1, "term '%s' has no %s (scripts/terms_table.py)" % (flag, col))
except (OSError, SyntaxError) as e:
    problem("scripts/terms_table.py", 1, "cannot load: %s" % e)

# ---------------------------------------------------------------------------------------------
# (g) generated text is current

_spec = importlib.util.spec_from_file_location("smg_bench_report", os.path.join(ROOT, "bench", "report.py"))
report = importlib.util.module_from_spec(_spec)
try:
    _spec.loader.exec_module(report)
except (OSError, SyntaxError) as e:
    problem("bench/report.py", 1, "cannot load: %s" % e)
    report = None
if report is not None:
    readme = TEXT.get("README.md", "")
    b, e = report.HIGHLIGHTS_BEGIN, report.HIGHLIGHTS_END
    if b not in readme or e not in readme:
        problem("README.md", 1, "no '%s' ... '%s' block (bench/report.py --readme README.md fills it)" % (b, e))
    else:
        have = readme[readme.index(b) + len(b):readme.index(e)].lstrip("\n")
        want = report.highlights(os.path.join(ROOT, "bench", "results"),
                                 os.path.join(ROOT, "docs", "results.md"))
        if have != want:
            a, w = have.split("\n"), want.split("\n")
            k = next((i for i in range(min(len(a), len(w))) if a[i] != w[i]), min(len(a), len(w)))
            line = readme[:readme.index(b)].count("\n") + 2 + k
            problem("README.md", line, "the highlights differ from what bench/report.py generates from "
                    "bench/results and docs/results.md (run: python3 bench/report.py --readme README.md)")
    import io  # noqa: E402
    import contextlib  # noqa: E402
    buf = io.StringIO()
    old_argv = sys.argv
    sys.argv = ["report.py", os.path.join(ROOT, "bench", "results")]
    try:
        with contextlib.redirect_stdout(buf):
            report.main()
    finally:
        sys.argv = old_argv
    perf = TEXT.get("docs/performance.md")
    if perf is not None and perf != buf.getvalue().replace(os.path.join(ROOT, ""), ""):
        problem("docs/performance.md", 1, "differs from what bench/report.py generates from bench/results "
                "(run: python3 bench/report.py bench/results > docs/performance.md)")

# ---------------------------------------------------------------------------------------------
# (n) hand-written tables of figures say so: in docs/ and bench/notes/, a markdown table with a
# number in a cell lies between a generator's markers (scripts/ladder.sh's and failure_study.py's
# "<!-- ladder:X -->" ... "<!-- /ladder:X -->", scripts/terms_table.py's "<!-- terms:begin -->" ...
# "<!-- terms:end -->"), or the nearest non-blank line above it is "<!-- not generated: WHY -->".
# docs/performance.md is generated as a whole (section (g)); its hand tables are its notes'.
GENERATED_BLOCKS = [(re.compile(r"^\s*<!-- ladder:([\w-]+) -->\s*$"), "<!-- /ladder:%s -->"),
                    (re.compile(r"^\s*<!-- terms:begin -->\s*$"), "<!-- terms:end -->"),
                    (re.compile(r"^\s*<!-- smg:highlights begin -->\s*$"), "<!-- smg:highlights end -->")]
TABLE_SEP = re.compile(r"^\s*\|(\s*:?-{3,}:?\s*\|)+\s*$")
NUMBER_CELL = re.compile(r"^[*_`(~≈<>≤≥]*[−+-]?\d")
NOT_GENERATED = re.compile(r"^\s*<!-- not generated: \S.*-->\s*$")


def unmarked_tables(text):
    """Line numbers (1-based) of tables with a number in a cell, outside generated blocks and
    without a "<!-- not generated: WHY -->" line above."""
    lines = text.split("\n")
    found, fenced, end, n = [], False, None, 0
    while n < len(lines):
        line = lines[n]
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced and end is not None:
            if line.strip() == end:
                end = None
        elif not fenced:
            for start, stop in GENERATED_BLOCKS:
                m = start.match(line)
                if m:
                    end = stop % m.group(1) if "%s" in stop else stop
            if end is None and line.lstrip().startswith("|") and n + 1 < len(lines) \
                    and TABLE_SEP.match(lines[n + 1]):
                k = n + 2
                while k < len(lines) and lines[k].lstrip().startswith("|"):
                    k += 1
                cells = [c.strip() for row in lines[n + 2:k]
                         for c in re.split(r"(?<!\\)\|", row.strip().strip("|"))]
                if any(NUMBER_CELL.match(c) for c in cells):
                    above = n - 1
                    while above >= 0 and not lines[above].strip():
                        above -= 1
                    if above < 0 or not NOT_GENERATED.match(lines[above]):
                        found.append(n + 1)
                n = k
                continue
        n += 1
    return found


for f in sorted(TEXT):
    if f.endswith(".md") and (f.startswith("docs/") or f.startswith("bench/notes/")) \
            and f != "docs/performance.md":
        for n in unmarked_tables(TEXT[f]):
            problem(f, n, "a table of figures outside a generated block without "
                          "'<!-- not generated: WHY -->' on the line above it")

# ---------------------------------------------------------------------------------------------
# (o) statements that drift apart from the code, the data or each other. Each check is narrow: it
# names one kind of drift that happened, and says page:line.
DRIFT_PAGES = sorted(f for f in TEXT if f.endswith(".md") and (
    f == "README.md" or f.startswith("docs/") or f.startswith("bench/notes/")))


def paragraphs(text):
    """(first line number, [(line number, line)]) of each paragraph outside fenced blocks."""
    para = []
    for n, line in md_lines(text, strip_code=False):
        if line.strip():
            para.append((n, line))
        elif para:
            yield para
            para = []
    if para:
        yield para


def sentences(para):
    """(line number, sentence) of a paragraph's sentences (split after '.', ';' or ':' + space)."""
    text, starts = "", []
    for n, line in para:
        starts.append((len(text), n))
        text += line.strip() + " "
    pos = 0
    for m in list(re.finditer(r"(?<=[.;])\s+", text)) + [None]:
        end = m.start() if m else len(text)
        chunk = text[pos:end].strip()
        if chunk:
            line = max(n for off, n in starts if off <= pos)
            yield line, chunk
        pos = m.end() if m else len(text)


# (o1) A range right after the math pages it covers ("derivations in `docs/math/energy.md` and
# `docs/math/terms/`, E1–E25"; "`docs/math/skin.md`, S1–S19") that starts at those pages' first
# label of its prefix must end at their last: a label added to the pages must reach the range.
MATH_REF = r"`?(?:docs/)?math/(?:terms/|[\w-]+\.md|[\w-]+/)`?\)?"
WHOLE_RANGE = re.compile(r"((?:%s\s*(?:,\s*and|,|and)\s*)*%s)\s*,\s*(?:equations\s+)?([%s])(\d{1,2})"
                         r"\s*[-–]\s*\2(\d{1,2})\b" % (MATH_REF, MATH_REF, PREFIXES))


def math_pages_named(refs):
    pages = set()
    for m in re.finditer(r"math/(terms/|[\w-]+\.md|[\w-]+/)", refs):
        name = m.group(1)
        if name.endswith("/"):
            pages.update(f for f in MATH if f.startswith("docs/math/" + name))
        else:
            pages.add("docs/math/" + name)
    return pages


for f in DRIFT_PAGES:
    if f in MATH:
        continue
    for n, line in md_lines(TEXT[f], strip_code=False):
        for m in WHOLE_RANGE.finditer(line):
            pages = math_pages_named(m.group(1))
            prefix, lo, hi = m.group(2), int(m.group(3)), int(m.group(4))
            nums = sorted(int(l[1:]) for l, p in page_of.items() if l[0] == prefix and p in pages)
            if nums and lo == nums[0] and hi != nums[-1]:
                problem(f, n, "range %s%d–%s%d after %s: those pages define %s%d–%s%d (extend the range)"
                        % (prefix, lo, prefix, hi, ", ".join(sorted(pages)), prefix, nums[0], prefix,
                           nums[-1]))

# (o2) The fused CUDA step said not to have run on a GPU (or not to be measured) while
# bench/results/gpu/ holds a GPU run of it: a sentence that names the fused step on the GPU and
# says it has not run, was written without a GPU or is not measured.
FUSED_RUNS = sorted(f for f in TEXT if f.startswith("bench/results/gpu/")
                    and re.search(r"fused[^\n]*\d\s*ms", TEXT[f], re.I))
FUSED_CUDA = re.compile(r"fused (?:CUDA )?step|smg::cuda::regularizers", re.I)
GPU_WORD = re.compile(r"CUDA|GPU|smg::cuda")
NOT_RUN = re.compile(r"\b(?:has|have|had) not (?:yet )?(?:been )?(?:run|measured)\b|\bnot (?:yet )?run on "
                     r"(?:a|the) GPU\b|\bwritten without a GPU\b|\bnot (?:yet )?measured\b|\bnever run\b",
                     re.I)
if FUSED_RUNS:
    for f in DRIFT_PAGES:
        for para in paragraphs(TEXT[f]):
            for n, sentence in sentences(para):
                if FUSED_CUDA.search(sentence) and GPU_WORD.search(sentence) and NOT_RUN.search(sentence):
                    problem(f, n, "says the fused CUDA step has not run or is not measured ('%s'), but %s "
                            "holds a GPU run of it" % (NOT_RUN.search(sentence).group(0), FUSED_RUNS[0]))

# (o3) One figure stated on several pages must be the same figure everywhere: (what, pages, the
# pattern whose group 1 is the figure, within a sentence).
SAME_FIGURE = [
    ("scripts/test.sh's duration", ("README.md", "docs/contributing.md"),
     re.compile(r"`scripts/test\.sh`[^.`]*?(?:takes|:)\s+(?:about\s+)?(\d+(?:\s*[–-]\s*\d+)?)\s+minutes")),
]
for what, pages, pattern in SAME_FIGURE:
    found = []  # (page, line, figure)
    for f in pages:
        for para in paragraphs(TEXT.get(f, "")):
            for n, sentence in sentences(para):
                for m in pattern.finditer(sentence):
                    found.append((f, n, re.sub(r"\s*[–-]\s*", "–", m.group(1))))
    for f, n, figure in found:
        other = next(((g, k, x) for g, k, x in found if x != figure), None)
        if other:
            problem(f, n, "%s stated as %s here and as %s at %s:%d (state one figure)"
                    % (what, figure, other[2], other[0], other[1]))

if HELP_MISSING:
    print("check_docs: note: not built, so their flag values were not checked: %s (build/release/examples)"
          % ", ".join(sorted(HELP_MISSING)), file=sys.stderr)
for p in problems:
    print(p)
sys.exit(1 if problems else 0)
