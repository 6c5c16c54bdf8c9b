#!/usr/bin/env python3
"""Reads smg_trainer's per-frame PLY files (OUT/ply/frame_<t>.ply; issue 36, docs/trainer.md
"Per-frame PLY") with readers the trainer's code has no part in.

    test_ply_readers.py --trainer build/release/examples/smg_trainer   (runs --quick)
    test_ply_readers.py --run OUT                                       (an existing run)

1. numpy, the way the original 3DGS code loads a PLY (GaussianModel.load_ply, which reads with
   plyfile then takes columns by name): the header is parsed as plyfile does it (format, element,
   typed properties), the body is one numpy structured array of the declared types, and the
   columns are gathered by name: xyz, f_dc_0..2, opacity, scale_*, rot_* sorted by their index.
   It checks the format line, the property order of 3DGS (x y z nx ny nz f_dc_0..2 opacity
   scale_0..2 rot_0..3), the file size, one file per frame (metrics.json's T), the Gaussian count
   (metrics.json's gaussians), unit quaternions, finite values, colours C0 * f_dc + 0.5 within
   [0, 1] for most rows, and motion: the first gaussians_static rows equal in every frame, the
   dynamic rows move between the first and the last frame.
2. meshio (Debian's python3-meshio, its own PLY reader), when installed: the same points and the
   same per-vertex columns, bit for bit.
Needs numpy (exits 77, ctest's SKIP_RETURN_CODE, with one "skipped" line without it).
"""
import argparse
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from script_test import ScriptTest  # noqa: E402

try:
    import numpy as np
except ImportError:
    sys.exit(ScriptTest("ply_readers").skip("numpy is not installed (scripts/deps.sh python3-numpy)"))

C0 = 0.28209479177387814
LAYOUT = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
          "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
PLY_TYPES = {"float": "f4", "float32": "f4", "double": "f8", "float64": "f8", "uchar": "u1", "uint8": "u1",
             "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4", "short": "i2", "ushort": "u2"}


def read_ply(path):
    """(format line, vertex count, [(name, numpy type)], structured array) of a binary PLY."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode("ascii").splitlines()
    assert lines[0] == "ply", lines[0]
    fmt = next(l for l in lines if l.startswith("format "))
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}[fmt.split()[1]]
    count, props, element = None, [], None
    for l in lines:
        w = l.split()
        if w[0] == "element":
            element = w[1]
            if element == "vertex":
                count = int(w[2])
        elif w[0] == "property" and element == "vertex":
            assert w[1] != "list", "list property in the vertex element"
            props.append((w[2], order + PLY_TYPES[w[1]]))
    body = np.frombuffer(data, dtype=np.dtype(props), count=count, offset=end)
    return fmt, count, props, body, len(data) - end


def gaussians_like_3dgs(v):
    """The arrays 3DGS's load_ply builds (for SH degree 0)."""
    xyz = np.stack((np.asarray(v["x"]), np.asarray(v["y"]), np.asarray(v["z"])), axis=1)
    opacities = np.asarray(v["opacity"])[..., np.newaxis]
    features_dc = np.zeros((xyz.shape[0], 3, 1))
    for k in range(3):
        features_dc[:, k, 0] = np.asarray(v["f_dc_%d" % k])
    names = v.dtype.names
    scale_names = sorted((p for p in names if p.startswith("scale_")), key=lambda x: int(x.split("_")[-1]))
    scales = np.stack([np.asarray(v[n]) for n in scale_names], axis=1)
    rot_names = sorted((p for p in names if p.startswith("rot")), key=lambda x: int(x.split("_")[-1]))
    rots = np.stack([np.asarray(v[n]) for n in rot_names], axis=1)
    return xyz, features_dc, opacities, scales, rots


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trainer", help="smg_trainer to run with --quick")
    ap.add_argument("--run", help="an existing run folder (OUT) instead")
    a = ap.parse_args()
    test = ScriptTest("ply_readers")
    expect = test.expect
    run = a.run
    if not run:
        run = tempfile.mkdtemp(prefix="smg_ply_readers_")
        test.run_quick_trainer(a.trainer, run, "--no-view")
    with open(os.path.join(run, "metrics.json")) as f:
        metrics = json.load(f)
    T, G, F = metrics["T"], metrics["gaussians"], metrics["gaussians_static"]

    names = sorted(os.listdir(os.path.join(run, "ply")))
    expect(names == sorted("frame_%d.ply" % t for t in range(T)), "one file per frame, frame_0..%d.ply" % (T - 1))
    frames = []
    for t in range(T):
        path = os.path.join(run, "ply", "frame_%d.ply" % t)
        fmt, count, props, v, body_bytes = read_ply(path)
        frames.append(gaussians_like_3dgs(v))
        if t in (0, T - 1):
            expect(fmt == "format binary_little_endian 1.0", "frame %d: %s" % (t, fmt))
            expect([p[0] for p in props] == LAYOUT and all(p[1] == "<f4" for p in props),
                   "frame %d: 3DGS's property layout, all float32" % t)
            expect(count == G and body_bytes == G * 4 * len(LAYOUT),
                   "frame %d: %d Gaussians (metrics.json: %d), %d bytes of data" % (t, count, G, body_bytes))
            expect(all(np.all(np.asarray(v[n]) == 0) for n in ("nx", "ny", "nz")), "frame %d: normals 0" % t)
    xyz0, dc0, op0, sc0, rot0 = frames[0]
    finite = all(np.all(np.isfinite(a)) for fr in frames for a in fr)
    expect(finite, "every value finite in every frame")
    qn = max(float(np.max(np.abs(np.linalg.norm(fr[4], axis=1) - 1))) for fr in frames)
    expect(qn < 1e-5, "unit quaternions (w x y z): max | |q| - 1 | = %.1e" % qn)
    rgb = C0 * dc0[:, :, 0] + 0.5
    inside = float(np.mean((rgb >= -0.05) & (rgb <= 1.05)))
    expect(inside > 0.95, "colour C0 * f_dc + 0.5 within [0, 1] (+-0.05) on %.1f %% of the values" % (100 * inside))
    expect(bool(np.all(sc0 < np.log(10.0))) and float(np.median(sc0)) < np.log(0.5),
           "scales are logs of sigmas in metres: median exp(scale) %.4f m" % float(np.exp(np.median(sc0))))
    expect(float(np.std(op0)) > 0 and bool(np.all(np.abs(op0) < 50)),
           "opacity logits, not all equal (sigmoid mean %.3f)" % float(np.mean(1 / (1 + np.exp(-op0)))))
    same = all(np.array_equal(fr[0][:F], xyz0[:F]) and np.array_equal(fr[4][:F], rot0[:F]) for fr in frames)
    expect(same, "the %d static rows are equal in every frame" % F)
    moved = np.linalg.norm(frames[-1][0][F:] - xyz0[F:], axis=1)
    expect(G > F and float(np.median(moved)) > 1e-3,
           "the %d dynamic rows move between frames 0 and %d (median %.3f m)" % (G - F, T - 1, float(np.median(moved))))
    expect(all(np.array_equal(fr[k], frames[0][k]) for fr in frames for k in (1, 2, 3)),
           "colours, opacities and scales equal in every frame (only poses change)")

    try:
        import meshio
    except ImportError:
        meshio = None
        print("ply_readers: meshio not installed: its check skipped (scripts/deps.sh python3-meshio)")
    if meshio is not None:
        t = T // 2
        path = os.path.join(run, "ply", "frame_%d.ply" % t)
        m = meshio.read(path)
        _, _, _, v, _ = read_ply(path)
        xyz = gaussians_like_3dgs(v)[0]
        cols = [n for n in LAYOUT if n not in ("x", "y", "z")]
        expect(m.points.shape == (G, 3) and np.array_equal(m.points.astype(np.float32), xyz.astype(np.float32)),
               "meshio %s reads frame %d: %s points equal to numpy's" % (meshio.__version__, t, m.points.shape))
        expect(sorted(m.point_data) == sorted(cols) and
               all(np.array_equal(np.asarray(m.point_data[n], dtype=np.float32), np.asarray(v[n])) for n in cols),
               "meshio: the same %d per-vertex columns, bit for bit" % len(cols))
    return test.finish()


if __name__ == "__main__":
    sys.exit(main())
