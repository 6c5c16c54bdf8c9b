#!/usr/bin/env python3
"""Opens one of smg_trainer's per-frame PLY files in a real 3DGS viewer (issue 36, docs/trainer.md
"Per-frame PLY"): @mkkellogg/gaussian-splats-3d 0.4.7 (Three.js), from npm, in headless Chromium.

    test_ply_viewer.py --trainer build/release/examples/smg_trainer [--modules DIR] [--screenshot PNG]
    test_ply_viewer.py --run OUT ...            (the middle frame of an existing run)
    test_ply_viewer.py --ply OUT/ply/frame_8.ply ...

Runs `smg_trainer --quick` (which writes OUT/ply/frame_<t>.ply by default) unless --ply names a file,
installs the viewer with `npm ci` into --modules (package.json and package-lock.json of this folder;
reused while the lock file is unchanged), serves index.html, node_modules and the PLY over HTTP on
127.0.0.1, and drives Chromium over the DevTools protocol (the client in tests/support/browser.py
that tests/pipeline/test_view_html.py uses too, standard library only). It checks that:
  * the viewer's PLY loader reads as many splats as the file's header declares (the trainer's
    Gaussian count), with no console error or uncaught exception;
  * the screenshot is not blank: at least 2 % of its pixels differ from the black background.
Without chromium or npm, or when `npm ci` cannot reach a registry, it prints one "skipped" line
and exits 77 (ctest's SKIP_RETURN_CODE).
"""
import argparse
import base64
import hashlib
import http.server
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "support"))
from browser import browser, find_chromium  # noqa: E402
from script_test import ScriptTest  # noqa: E402


def ply_header(path):
    """(vertex count, property names, byte offset of the data) of a binary PLY."""
    with open(path, "rb") as f:
        head = f.read(4096)
    end = head.index(b"end_header\n") + len(b"end_header\n")
    lines = head[:end].decode("ascii").splitlines()
    count = next(int(l.split()[2]) for l in lines if l.startswith("element vertex"))
    names = [l.split()[2] for l in lines if l.startswith("property")]
    return count, names, end


def camera_for(path):
    """A camera looking at the middle of the Gaussians from the -y side, above (z is up)."""
    count, names, start = ply_header(path)
    with open(path, "rb") as f:
        f.seek(start)
        data = f.read()
    w = len(names)
    xyz = [struct.unpack_from("<3f", data, 4 * w * i) for i in range(count)]
    cols = [sorted(p[k] for p in xyz) for k in range(3)]
    mid = [c[len(c) // 2] for c in cols]
    lo = [c[len(c) // 20] for c in cols]
    hi = [c[len(c) * 19 // 20] for c in cols]
    size = max(h - l for h, l in zip(hi, lo))
    pos = [mid[0], mid[1] - 1.15 * size, mid[2] + 0.65 * size]
    return pos, mid


def png_pixels(png):
    """RGBA or RGB rows of an 8-bit non-interlaced PNG (what Chromium's screenshots are)."""
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, width = 8, b"", 0
    while pos < len(png):
        (n,) = struct.unpack(">I", png[pos:pos + 4])
        kind, body = png[pos + 4:pos + 8], png[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            width, height, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and ctype in (2, 6), (depth, ctype)
            bpp = 4 if ctype == 6 else 3
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = width * bpp
    rows, prev = [], bytearray(stride)
    for y in range(height):
        ft, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if ft == 1:
                line[i] = (line[i] + a) & 255
            elif ft == 2:
                line[i] = (line[i] + b) & 255
            elif ft == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif ft == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    return width, height, bpp, rows


def install_viewer(modules):
    """npm ci into `modules` (a copy of package.json + lock); None when done, else why not."""
    with open(os.path.join(HERE, "package-lock.json"), "rb") as f:
        lock = f.read()
    stamp = os.path.join(modules, "lock.sha256")
    digest = hashlib.sha256(lock).hexdigest()
    if os.path.isfile(stamp) and open(stamp).read() == digest:
        return None
    os.makedirs(modules, exist_ok=True)
    for name in ("package.json", "package-lock.json"):
        shutil.copy(os.path.join(HERE, name), os.path.join(modules, name))
    t0 = time.time()
    r = subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--ignore-scripts", "--loglevel=error"],
                       cwd=modules, capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        return "npm ci failed (no registry?): " + " ".join(r.stderr.split())[:200]
    with open(stamp, "w") as f:
        f.write(digest)
    print("ply_viewer: npm ci in %.1f s" % (time.time() - t0))
    return None


class Handler(http.server.SimpleHTTPRequestHandler):
    """index.html from this folder, /node_modules/ from the install, /ply/<name> from the run."""
    roots = {}

    def translate_path(self, path):
        path = path.split("?", 1)[0]
        for prefix, folder in self.roots.items():
            if path.startswith(prefix):
                return os.path.join(folder, *[p for p in path[len(prefix):].split("/") if p not in ("", "..")])
        return os.path.join(HERE, "index.html")

    def log_message(self, *args):
        pass


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trainer", help="smg_trainer to run with --quick")
    ap.add_argument("--run", help="an existing run folder (OUT) instead: its middle frame")
    ap.add_argument("--ply", help="a PLY file instead")
    ap.add_argument("--modules", help="where npm installs the viewer (default: a temporary folder)")
    ap.add_argument("--screenshot", help="write the viewer's picture here (PNG)")
    a = ap.parse_args()
    test = ScriptTest("ply_viewer")
    chromium = find_chromium()
    if not chromium:
        return test.skip("chromium is not installed (scripts/deps.sh chromium, as root)")
    if not shutil.which("npm"):
        return test.skip("npm is not installed (scripts/deps.sh npm, as root)")
    modules = a.modules or tempfile.mkdtemp(prefix="smg_ply_npm_")
    why = install_viewer(modules)
    if why:
        return test.skip(why)
    if a.ply:
        ply = a.ply
    else:
        run = a.run
        if not run:
            run = tempfile.mkdtemp(prefix="smg_ply_run_")
            test.run_quick_trainer(a.trainer, run, "--no-view")
        frames = sorted(int(n[6:-4]) for n in os.listdir(os.path.join(run, "ply")))
        ply = os.path.join(run, "ply", "frame_%d.ply" % frames[len(frames) // 2])
    count, names, _ = ply_header(ply)
    print("ply_viewer: %s: %d Gaussians, %d properties" % (ply, count, len(names)))
    pos, at = camera_for(ply)

    Handler.roots = {"/node_modules/": os.path.join(modules, "node_modules"),
                     "/ply/": os.path.dirname(os.path.abspath(ply))}
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = "http://127.0.0.1:%d/index.html?ply=/ply/%s&pos=%s&at=%s&up=0,0,1" % (
        server.server_address[1], os.path.basename(ply), ",".join("%.4f" % v for v in pos),
        ",".join("%.4f" % v for v in at))

    expect = test.expect
    t_start = time.time()
    try:
        with browser(chromium, "smg_ply_profile_") as dt:
            dt.open_page(url, 800, 600)
            t0 = time.time()
            state = {}
            while time.time() < t0 + 60:
                state = dt.evaluate("window.__plyTest || {}") or {}
                if state.get("ready") or state.get("error"):
                    break
                time.sleep(0.2)
            print("ply_viewer: page loaded, file read and %d frames drawn in %.1f s" % (state.get("frames", 0), time.time() - t0))
            expect(not state.get("error"), "the viewer loaded the file (%s)" % (state.get("error") or "no error")[:300])
            expect(state.get("count") == count,
                   "the viewer's PLY loader read %s splats; the header declares %d" % (state.get("count"), count))
            errors = dt.errors()
            expect(not errors, "no console error or exception (%s)" % "; ".join(errors)[:300])
            png = base64.b64decode(dt.call("Page.captureScreenshot", {"format": "png"})["data"])
            if a.screenshot:  # at 0.7 scale: the docs' picture stays near 150 KiB
                small = base64.b64decode(dt.call("Page.captureScreenshot", {"format": "png", "clip": {
                    "x": 0, "y": 40, "width": 800, "height": 460, "scale": 0.7}})["data"])
                with open(a.screenshot, "wb") as f:
                    f.write(small)
                print("ply_viewer: screenshot %s (%d bytes)" % (a.screenshot, len(small)))
            w, h, bpp, rows = png_pixels(png)
            lit = sum(1 for row in rows for i in range(0, len(row), bpp) if max(row[i:i + 3]) > 24)
            expect(lit >= 0.02 * w * h, "the screenshot is not blank: %.1f %% of %dx%d pixels lit" % (100.0 * lit / (w * h), w, h))
    finally:
        server.shutdown()
    print("ply_viewer: browser part in %.1f s" % (time.time() - t_start))
    return test.finish()


if __name__ == "__main__":
    sys.exit(main())
