#!/usr/bin/env python3
"""Writes the small MoSca scene beside this script (tests/data/mosca_small), with numpy and the
standard library only (the PNG writer of ../som_small/make_fixture.py), following MoSca's conventions (JiahuiLei/MoSca
lib_prior/prior_loading.py::Saved2D, data_utils/iphone_helpers.py, lib_prior/tracking/
bootstapir_wrapper.py writes its tracks with np.savez_compressed):

  images/<frame>.png                     RGBA, half of the cameras' image_size (as the iPhone release)
  cameras/<frame>.json                   Nerfies JSON at full size (image_size [2W, 2H])
  sensor_depth/<frame>.npz               np.savez_compressed(dep=float32 [H, W]), 0 = no depth
  epi/error/<frame>.png.npy              float32 [H, W] epipolar error (> 0.001 = dynamic)
  test_images/, test_cameras/, test_covisible/  camera 1 at time 1 (covisible: pixel > 0)
  uniform_dep=sensor_bootstapir_tap.npz  tracks [T, N, 2] float32, visibility [T, N] bool, queries [N, 3]
  dynamic_dep=sensor_bootstapir_tap.npz  a second file, concatenated along N (no queries)
  vos_deva/Annotations/<frame>.png       RGB(A) instance ids (R + 256 G + 65536 B)

The scene: a plane at 2 m, a square at 1 m moving 1 px per frame to the right (as som_small),
camera 0 at the origin looking down +z. Tests (tests/trainer/test_layout_mosca.cpp) check the
values this script writes. Run: /usr/bin/python3 tests/data/mosca_small/make_fixture.py
"""
import importlib.util
import json
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
W, H, T = 16, 12, 3
FOCAL = 40.0          # at full size (32 x 24): 20 px at the images' size
PP = [15.5, 11.5]     # full-size integer-centre principal point; halved: 7.75, 5.75


def _som_fixture():
    """som_small's script (the same tiny scene): its PNG writer and moving square are reused."""
    spec = importlib.util.spec_from_file_location("som_fixture", os.path.join(HERE, "..", "som_small", "make_fixture.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SOM = _som_fixture()
png, square = SOM.png, SOM.square  # grey [H, W] or RGBA [H, W, 4] PNGs (PIL is not installed)


def camera(x):
    return {"orientation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "position": [x, 0.0, 0.0], "focal_length": FOCAL,
            "principal_point": PP, "skew": 0.0, "pixel_aspect_ratio": 1.0, "radial_distortion": [0.0, 0.0, 0.0],
            "tangential_distortion": [0.0, 0.0], "image_size": [2 * W, 2 * H]}


def rgb(t):
    a = np.full((H, W, 4), 255, np.uint8)
    a[..., 0] = np.where(square(t), 200, 40)
    a[..., 1] = 10 * np.arange(W)[None, :]
    a[..., 2] = 20 * np.arange(H)[:, None]
    return a


def main():
    for d in ["images", "cameras", "sensor_depth", "epi/error", "test_images", "test_cameras", "test_covisible",
              "vos_deva/Annotations"]:
        os.makedirs(os.path.join(HERE, d), exist_ok=True)
    train = [f"0_{t:05d}" for t in range(T)]
    for t, name in enumerate(train):
        with open(os.path.join(HERE, "cameras", name + ".json"), "w") as f:
            json.dump(camera(0.0), f, indent=2)
        png(os.path.join(HERE, "images", name + ".png"), rgb(t))
        dep = np.where(square(t), 1.0, 2.0).astype(np.float32)
        dep[0, 0] = 0.0       # no depth
        dep[0, 1] = 5000.0    # beyond MoSca's 1000 m clip: invalid
        np.savez_compressed(os.path.join(HERE, "sensor_depth", name + ".npz"), dep=dep)
        err = np.where(square(t), 0.01, 0.0005).astype(np.float32)  # either side of epi_th 0.001
        # MoSca names each map after its image file (epi_analysis.py, `thread`): 0_00000.png.npy.
        np.save(os.path.join(HERE, "epi/error", name + ".png.npy"), err)
        inst = np.zeros((H, W, 4), np.uint8)
        inst[..., 3] = 255
        inst[square(t), :3] = [1, 1, 0]     # id 257
        inst[10:, :, :3] = [5, 0, 0]        # id 5 (the floor)
        png(os.path.join(HERE, "vos_deva/Annotations", name + ".png"), inst)
    with open(os.path.join(HERE, "test_cameras", "1_00001.json"), "w") as f:
        json.dump(camera(0.1), f, indent=2)
    png(os.path.join(HERE, "test_images", "1_00001.png"), rgb(1))
    png(os.path.join(HERE, "test_covisible", "1_00001.png"), np.where(np.arange(W)[None, :] < 12, 7, 0) * np.ones((H, 1)))
    # Uniform file: the square's 16 points at time 0 plus 2 background points; the square moves
    # 1 px per frame; the last background point is invisible at t = 2; the second background
    # point is at x = 16.2 at t = 1 (outside: visibility cleared by the reader).
    ys, xs = np.nonzero(square(0))
    pts = np.concatenate([np.stack([xs, ys], 1), [[0, 0], [15, 11]]]).astype(np.float32)
    tracks = np.repeat(pts[None], T, 0)
    for t in range(T):
        tracks[t, :16, 0] += t
    tracks[1, 17, 0] = 16.2
    vis = np.ones((T, len(pts)), bool)
    vis[2, 16] = False
    queries = np.concatenate([np.zeros((len(pts), 1)), pts[:, ::-1]], 1).astype(np.float32)  # (t, y, x)
    np.savez_compressed(os.path.join(HERE, "uniform_dep=sensor_bootstapir_tap.npz"), tracks=tracks, visibility=vis,
                        queries=queries)
    # Dynamic file: two points, the first invisible at t = 0 (query = first visible frame, 1).
    dyn = np.array([[[5.25, 4.75], [6.0, 6.0]], [[6.25, 4.75], [7.0, 6.0]], [[7.25, 4.75], [8.0, 6.0]]], np.float32)
    dvis = np.array([[False, True], [True, True], [True, True]])
    np.savez_compressed(os.path.join(HERE, "dynamic_dep=sensor_bootstapir_tap.npz"), tracks=dyn, visibility=dvis)


if __name__ == "__main__":
    main()
