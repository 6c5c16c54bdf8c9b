#!/usr/bin/env python3
"""Checks OUT/view.html of an smg_trainer run in a real browser (issue 26, docs/trainer.md "view.html").

    test_view_html.py --trainer build/rel/examples/smg_trainer [--work DIR] [--screenshots DIR] [--page OUT]

Runs `smg_trainer --quick --out DIR/run` (or uses the run in --page), opens DIR/run/view.html in
headless Chromium (Debian's `chromium`; scripts/test.sh installs it as root) and drives it over the
DevTools protocol on --remote-debugging-pipe with the standard library only. It checks that:
  * the page loads with no console error and no uncaught exception;
  * the canvas is not blank (at least 1% of its pixels differ from the background);
  * moving the time slider to the last frame changes the drawn pixels;
  * the embedded data round-trips: node positions decoded by the page at the first, a middle and
    the last frame match OUT/view_nodes.npy to 1e-4 of the scene extent (the uint16 quantisation
    bounds the error by half a step, at most 7.7e-6 of the box per axis), the page's T, N and
    metrics equal metrics.json's, and every confidence lies in [0, 1];
  * the page fetches nothing but itself and its own images (file:, blob:, data: URLs only), and
    its base64 block decodes with Python's base64 module (validate=True) to the bytes the page read;
  * clicking a node (the test hook's select) fills the node panel with its c(t) plot.
It prints the frame rates of 30 frames drawn back to back (requestAnimationFrame), and with
--screenshots writes the docs' pictures. Without chromium it prints one "skipped" line and exits
77 (ctest's SKIP_RETURN_CODE).
"""
import argparse
import base64
import json
import os
import shutil
import struct
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from browser import browser, find_chromium  # noqa: E402
from script_test import ScriptTest  # noqa: E402


def read_npy_float32(path):
    """A little-endian float32 .npy in C order: (shape, flat list)."""
    with open(path, "rb") as f:
        data = f.read()
    assert data[:6] == b"\x93NUMPY", path
    major = data[6]
    if major == 1:
        (hlen,) = struct.unpack_from("<H", data, 8)
        start = 10
    else:
        (hlen,) = struct.unpack_from("<I", data, 8)
        start = 12
    header = data[start:start + hlen].decode("latin1")
    assert "'<f4'" in header and "'fortran_order': False" in header, header
    shape = tuple(int(x) for x in header.split("'shape': (")[1].split(")")[0].split(",") if x.strip())
    count = 1
    for d in shape:
        count *= d
    values = struct.unpack_from("<%df" % count, data, start + hlen)
    return shape, values


def screenshot(dt, path):
    # At 0.7 scale: the docs' pictures stay under 200 KiB.
    png = base64.b64decode(dt.call("Page.captureScreenshot", {"format": "png", "clip": {
        "x": 0, "y": 0, "width": 1280, "height": 760, "scale": 0.7}})["data"])
    with open(path, "wb") as f:
        f.write(png)
    print("view_html: screenshot %s (%d bytes)" % (path, len(png)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trainer", help="smg_trainer to run with --quick")
    ap.add_argument("--page", help="an existing run folder instead (view.html, view_nodes.npy, metrics.json)")
    ap.add_argument("--work", help="scratch folder (default: a temporary one)")
    ap.add_argument("--screenshots", help="write view_frame.png and view_node.png here")
    ap.add_argument("--fps-frames", type=int, default=30)
    a = ap.parse_args()

    test = ScriptTest("view_html")
    chromium = find_chromium()
    if not chromium:
        return test.skip("chromium is not installed (scripts/deps.sh chromium, as root)")
    work = a.work or tempfile.mkdtemp(prefix="smg_view_")
    os.makedirs(work, exist_ok=True)
    if a.page:
        run = a.page
    else:
        run = os.path.join(work, "run")
        test.run_quick_trainer(a.trainer, run, "--no-ply")
    page = os.path.abspath(os.path.join(run, "view.html"))
    print("view_html: %s is %d bytes" % (page, os.path.getsize(page)))
    with open(os.path.join(run, "metrics.json")) as f:
        metrics = json.load(f)
    shape, positions = read_npy_float32(os.path.join(run, "view_nodes.npy"))
    with open(page, encoding="utf-8") as f:
        html = f.read()

    expect = test.expect
    try:
        with browser(chromium, "smg_view_profile_") as dt:
            dt.open_page("file://" + page, 1280, 760, ("Runtime", "Log", "Page", "Network"))
            deadline = time.time() + 30
            while not dt.evaluate("!!(window.__smgView && window.__smgView.ready)"):
                if time.time() > deadline or dt.errors():
                    break
                time.sleep(0.1)
            expect(dt.evaluate("!!(window.__smgView && window.__smgView.ready)") is True, "the page's script ran")
            if test.failures:
                raise RuntimeError("; ".join(dt.errors()) or "the page did not start")

            T, N = dt.evaluate("__smgView.frameCount"), dt.evaluate("__smgView.nodeCount")
            expect((T, N, 3) == shape, "T, N = %d, %d as in view_nodes.npy %s" % (T, N, shape))
            expect(T == metrics["T"] and N == metrics["nodes"], "T and N as in metrics.json")
            expect(dt.evaluate("__smgView.header.metrics") == metrics, "the header's metrics equal metrics.json")
            extent = metrics["extent"]
            for t in (0, T // 2, T - 1):
                got = dt.evaluate("__smgView.nodesAt(%d)" % t)
                want = positions[t * N * 3:(t + 1) * N * 3]
                err = max(abs(g - w) for g, w in zip(got, want))
                expect(len(got) == N * 3 and err <= 1e-4 * extent,
                       "node positions at frame %d round-trip: max error %.2e m (%.1e of the extent)" % (t, err, err / extent))
            # The C++ base64 encoder against Python's decoder: the block decodes strictly, to the
            # bytes the page decoded (its nodes array, quantised, read back through the header).
            block = html.split('<script type="application/octet-stream" id="smg-data">', 1)[1].split("</script>", 1)[0]
            blob = base64.b64decode(block.strip(), validate=True)
            nodes = dt.evaluate("__smgView.header.arrays.nodes")
            lo, step = dt.evaluate("__smgView.header.quant.lo"), dt.evaluate("__smgView.header.quant.step")
            q = struct.unpack_from("<%dH" % (nodes["bytes"] // 2), blob, nodes["offset"])
            page_t0 = dt.evaluate("__smgView.nodesAt(0)")
            expect(len(blob) == dt.evaluate("atob(document.getElementById('smg-data').textContent.trim()).length")
                   and all(abs(lo[k % 3] + q[k] * step[k % 3] - page_t0[k]) <= 1e-6 * extent for k in range(N * 3)),
                   "the data block (%d bytes) decodes with Python's base64 to what the page decoded" % len(blob))
            conf = dt.evaluate("[].concat(...Array.from({length: __smgView.frameCount}, (_, t) => __smgView.confidenceAt(t)))")
            expect(len(conf) == T * N and all(0 <= c <= 1 for c in conf) and max(conf) > min(conf),
                   "confidences [T][N] in [0, 1], not constant")

            first = dt.evaluate("__smgView.pixels()")
            lit = first["lit"] / (first["width"] * first["height"])
            expect(lit > 0.01, "the canvas is not blank: %.1f%% of %dx%d pixels drawn" % (100 * lit, first["width"], first["height"]))
            if a.screenshots:  # without the Gaussian centres, whose noise would triple the PNGs
                os.makedirs(a.screenshots, exist_ok=True)
                dt.evaluate("__smgView.show('gaussians', false); __smgView.setFrame(%d)" % (T // 2))
                screenshot(dt, os.path.join(a.screenshots, "view_frame.png"))
                dt.evaluate("__smgView.show('gaussians', true); __smgView.setFrame(0)")
            dt.evaluate("(() => { const s = document.getElementById('time'); s.value = String(%d); "
                        "s.dispatchEvent(new Event('input')); })()" % (T - 1))
            moved = dt.evaluate("__smgView.pixels()")
            expect(dt.evaluate("__smgView.frame()") == T - 1 and moved["hash"] != first["hash"] and moved["lit"] > 0,
                   "moving the slider to frame %d changes the drawn pixels" % (T - 1))
            pictures = dt.evaluate("document.querySelectorAll('#images img').length")
            expect(pictures > 0, "the images panel shows %d pictures at the last frame" % pictures)

            dt.evaluate("__smgView.setColour('class'); __smgView.select(0)")
            expect(dt.evaluate("!document.getElementById('node-panel').hidden && "
                               "document.getElementById('node-title').textContent.startsWith('node 0')"),
                   "selecting node 0 shows its panel and c(t) plot")
            if a.screenshots:
                dt.evaluate("__smgView.show('gaussians', false); __smgView.show('cut', true); "
                            "__smgView.setFrame(%d); __smgView.select(%d)" % (T // 2, N // 2))
                screenshot(dt, os.path.join(a.screenshots, "view_node.png"))
                dt.evaluate("__smgView.show('gaussians', true); __smgView.show('cut', false)")
            dt.evaluate("__smgView.select(-1); __smgView.setColour('confidence')")

            c = dt.evaluate("__smgView.counts")
            for mode in ("time", "orbit"):
                fps = dt.evaluate("__smgView.measureFps(%d, '%s')" % (a.fps_frames, mode), timeout=120)
                print("view_html: %s: %.1f frames per second over %d frames in headless Chromium (SwiftShader WebGL), "
                      "%d nodes, %d edges, %d + %d Gaussian centres" % (mode, fps, a.fps_frames, N, c["edges"], c["S"], c["D"]))
            fetched = sorted({m["params"]["request"]["url"].split(":", 1)[0] for m in dt.events
                              if m.get("method") == "Network.requestWillBeSent"})
            expect(set(fetched) <= {"file", "blob", "data"}, "nothing fetched but the page and its own images (%s)"
                   % ", ".join(fetched))
            errors = dt.errors()
            expect(not errors, "no console errors" + ("" if not errors else ": " + " | ".join(errors)))
    finally:
        if not a.work and not a.page:
            shutil.rmtree(work, ignore_errors=True)
    return test.finish()


if __name__ == "__main__":
    sys.exit(main())
