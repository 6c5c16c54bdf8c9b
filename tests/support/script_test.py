"""The frame the standalone test scripts share (tests/pipeline/test_view_html.py and
test_ply_readers.py, tests/ply_viewer/test_ply_viewer.py): one "ok"/"FAIL" line per check, the
"skipped" line and exit code 77 that ctest's SKIP_RETURN_CODE reads, the closing summary, and the
short `smg_trainer --quick` run they look at. Standard library only; the scripts find this folder
from their own path, so they run from a fresh clone as ctest calls them."""
import subprocess
import time


class ScriptTest:
    """The checks of one test script, each line prefixed with the script's ctest name."""

    def __init__(self, name):
        self.name = name
        self.failures = []

    def expect(self, ok, what):
        """Prints one check's line and keeps the failed ones for finish()."""
        print("%s: %s %s" % (self.name, "ok  " if ok else "FAIL", what))
        if not ok:
            self.failures.append(what)

    def skip(self, why):
        """Prints the one "skipped" line and returns 77, ctest's SKIP_RETURN_CODE for these tests."""
        print("%s: skipped: %s" % (self.name, why))
        return 77

    def finish(self):
        """Prints the summary and returns the script's exit code: 1 if a check failed, else 0."""
        if self.failures:
            print("%s: %d check(s) failed" % (self.name, len(self.failures)))
            return 1
        print("%s: all checks passed" % self.name)
        return 0

    def run_quick_trainer(self, trainer, out, without):
        """Runs `trainer --quick` into `out`, without pictures and without `without` (the output the
        script does not read, e.g. "--no-view"), and prints how long it took."""
        t0 = time.time()
        # --stage2-iters 60 (quick: 300): the outputs are of the same kind, each test about 7 s faster.
        subprocess.run([trainer, "--quick", "--stage2-iters", "60", "--quiet", "--no-pictures", without, "--out", out],
                       check=True, stdout=subprocess.DEVNULL)
        print("%s: smg_trainer --quick --stage2-iters 60 in %.1f s" % (self.name, time.time() - t0))
