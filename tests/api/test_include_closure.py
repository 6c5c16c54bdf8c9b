#!/usr/bin/env python3
"""No device header reaches the CPU thread pool (docs/contributing.md section 2).

The include closure of every include/smg/cuda/*.cuh, followed through every `#include "smg/..."`
line whatever #if surrounds it (so the check errs on the strict side), must not contain
smg/core/parallel.hpp (the pool, its ParallelOptions and Executor) nor a header that includes
<thread> or <condition_variable> itself (a pool of its own; a host-side <mutex>, as common.cuh's
device-property cache, is no pool). Why: a CUDA translation unit (nvcc, a torch
extension's .cu) should compile only the element maths, views, options and checks it runs, and
the CPU loops' threads are no part of a kernel. Prints one line per header (clean, or the include
path that leaks) and exits 1 naming each leak. `--self-test` plants a leak in a copy of the tree
and checks that it is found (run by ctest too, so that the check itself can fail)."""
import os
import re
import shutil
import sys
import tempfile
from collections import deque

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
POOL = "smg/core/parallel.hpp"
THREAD_HEADERS = ("thread", "condition_variable")
INCLUDE = re.compile(r'^\s*#\s*include\s+"(smg/[^"]+)"', re.M)
SYSTEM = re.compile(r"^\s*#\s*include\s+<(\w+)>", re.M)


def includes(include_dir, header):
    with open(os.path.join(include_dir, header), encoding="utf-8") as f:
        text = f.read()
    return INCLUDE.findall(text), set(SYSTEM.findall(text))


def leak(include_dir, start):
    """The include path from `start` to the first header that is, or itself includes, the CPU
    pool (breadth first: the shortest such path), or None."""
    prev = {start: None}
    queue = deque([start])
    while queue:
        h = queue.popleft()
        if not os.path.exists(os.path.join(include_dir, h)):
            return [start, "... " + h + " (missing)"]
        local, system = includes(include_dir, h)
        bad = None
        if h == POOL:
            bad = h
        elif system & set(THREAD_HEADERS):
            bad = h + " <" + sorted(system & set(THREAD_HEADERS))[0] + ">"
        if bad:
            path = []
            x = prev[h]
            while x:
                path.append(x)
                x = prev[x]
            return path[::-1] + [bad]
        for n in local:
            if n not in prev:
                prev[n] = h
                queue.append(n)
    return None


def check(include_dir, out=sys.stdout):
    cuda = os.path.join(include_dir, "smg", "cuda")
    headers = sorted(f for f in os.listdir(cuda) if f.endswith(".cuh"))
    leaks = 0
    for f in headers:
        p = leak(include_dir, "smg/cuda/" + f)
        if p:
            leaks += 1
            print("include closure: LEAK %s reaches the CPU pool: %s" % (f, " -> ".join(p)), file=out)
        else:
            print("include closure: clean %s" % f, file=out)
    return len(headers), leaks


def self_test():
    """A copy of include/ with one device header made to include the pool must fail, naming it."""
    tmp = tempfile.mkdtemp(prefix="smg_closure_")
    try:
        inc = os.path.join(tmp, "include")
        shutil.copytree(os.path.join(ROOT, "include"), inc)
        victim = os.path.join(inc, "smg", "cuda", "common.cuh")
        with open(victim, encoding="utf-8") as f:
            text = f.read()
        with open(victim, "w", encoding="utf-8") as f:
            f.write(text.replace('#include "smg/core/types.hpp"',
                                 '#include "smg/core/types.hpp"\n#include "smg/skin/blend.hpp"', 1))
        with open(os.devnull, "w") as null:
            n, leaks = check(inc, null)
        # common.cuh is included by every other device header: all of them leak.
        if leaks != n:
            print("self-test FAILED: a planted leak in common.cuh was found in %d of %d headers" % (leaks, n))
            return 1
        p = leak(inc, "smg/cuda/common.cuh")
        if p is None or p[-1] != POOL or "smg/skin/blend.hpp" not in p:
            print("self-test FAILED: the path does not name the planted include: %s" % p)
            return 1
        print("include closure self-test: ok (a planted include of skin/blend.hpp in common.cuh: %d of %d leak, path %s)"
              % (leaks, n, " -> ".join(p)))
        return 0
    finally:
        shutil.rmtree(tmp)


def main(argv):
    if argv[1:] == ["--self-test"]:
        return self_test()
    if argv[1:]:
        print("usage: test_include_closure.py [--self-test]", file=sys.stderr)
        return 2
    n, leaks = check(os.path.join(ROOT, "include"))
    if leaks:
        print("include closure: %d of %d device headers reach the CPU pool" % (leaks, n))
        return 1
    print("include closure: ok (%d device headers, none reaches %s)" % (n, POOL))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
