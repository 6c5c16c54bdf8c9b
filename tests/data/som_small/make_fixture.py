#!/usr/bin/env python3
"""Writes the small Shape-of-Motion scene beside this script (tests/data/som_small), with numpy
and the standard library only, following the conventions of SoM's loader
(vye16/shape-of-motion flow3d/data/iphone_dataset.py::iPhoneDataset, camera_type "original",
depth_type "depth_anything_lidar", factor 1; flow3d/data/utils.py::parse_tapir_track_info):

  splits/{train,val}.json, extra.json, camera/<frame>.json (Nerfies), rgb/1x/<frame>.png (RGBA),
  flow3d_preprocessed/aligned_depth_anything_lidar/1x/<frame>.npy  float32 disparity [H, W]
  flow3d_preprocessed/track_anything/1x/<frame>.png                 0/255 grey
  flow3d_preprocessed/covisible/1x/val/<frame>.png                  0/255 grey
  flow3d_preprocessed/2d_tracks/1x/<q>_<t>.npy                      float32 [N_q, 4]

It also writes tests/data/som_colmap (an overlay: copied over som_small it makes the scene SoM
reads with its defaults, camera_type "refined" and depth_type "depth_anything_colmap"):

  flow3d_preprocessed/colmap/sparse/{cameras,images}.bin   COLMAP's binary model, written with
      struct in COLMAP's layout (colmap/scripts/python/read_write_model.py, write_cameras_binary
      and write_images_binary, the functions SoM's flow3d/data/colmap.py reads back)
  flow3d_preprocessed/colmap/scale.npy                      float64 0-d: COLMAP units -> metres
  flow3d_preprocessed/aligned_depth_anything_colmap/1x/<frame>.npy  float32 disparity in COLMAP units

The scene: a fronto-parallel plane at 2 m, a square at 1 m moving 1 px per frame to the right,
camera 0 at the origin looking down +z (identity orientation). Track rows: x, y (integer pixel
centres), occlusion logit, expected-distance logit. Tests (tests/trainer/test_layout_som.cpp) check
the values this script writes. Run: /usr/bin/python3 tests/data/som_small/make_fixture.py
"""
import json
import os
import struct
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
W, H, T = 16, 12, 3
FOCAL = 20.0
PP = [7.5, 5.5]  # SoM's integer-centre convention: the image centre of a 16 x 12 image


def png(path, array):
    """8-bit PNG (grey [H, W] or RGBA [H, W, 4]) written with zlib: PIL is not installed."""
    a = np.ascontiguousarray(array, dtype=np.uint8)
    h, w = a.shape[:2]
    colour = 0 if a.ndim == 2 else 6
    raw = b"".join(b"\x00" + a[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, colour, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def square(t):
    """The moving square's pixels at time t: columns 4+t .. 7+t, rows 4 .. 7."""
    m = np.zeros((H, W), bool)
    m[4:8, 4 + t:8 + t] = True
    return m


def camera(x):
    return {"orientation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "position": [x, 0.0, 0.0], "focal_length": FOCAL,
            "principal_point": PP, "skew": 0.0, "pixel_aspect_ratio": 1.0, "radial_distortion": [0.0, 0.0, 0.0],
            "tangential_distortion": [0.0, 0.0], "image_size": [W, H]}


def main():
    pre = os.path.join(HERE, "flow3d_preprocessed")
    for d in ["splits", "camera", "rgb/1x", "flow3d_preprocessed/aligned_depth_anything_lidar/1x",
              "flow3d_preprocessed/track_anything/1x", "flow3d_preprocessed/covisible/1x/val",
              "flow3d_preprocessed/2d_tracks/1x"]:
        os.makedirs(os.path.join(HERE, d), exist_ok=True)
    train = [f"0_{t:05d}" for t in range(T)]
    val = ["1_00001"]
    with open(os.path.join(HERE, "splits/train.json"), "w") as f:
        json.dump({"frame_names": train, "time_ids": list(range(T)), "camera_ids": [0] * T}, f)
    with open(os.path.join(HERE, "splits/val.json"), "w") as f:
        json.dump({"frame_names": val, "time_ids": [1], "camera_ids": [1]}, f)
    with open(os.path.join(HERE, "extra.json"), "w") as f:
        json.dump({"fps": 30.0, "factor": 1}, f)
    for name in train:
        with open(os.path.join(HERE, "camera", name + ".json"), "w") as f:
            json.dump(camera(0.0), f, indent=2)
    with open(os.path.join(HERE, "camera", val[0] + ".json"), "w") as f:
        json.dump(camera(0.1), f, indent=2)
    for t, name in enumerate(train + [None]):
        if name is None:
            name, t = val[0], 1
        m = square(t)
        rgba = np.zeros((H, W, 4), np.uint8)
        rgba[..., 0] = np.where(m, 200, 40)
        rgba[..., 1] = 10 * np.arange(W)[None, :]
        rgba[..., 2] = 20 * np.arange(H)[:, None]
        rgba[..., 3] = 255
        png(os.path.join(HERE, "rgb/1x", name + ".png"), rgba)
    png(os.path.join(pre, "covisible/1x/val", val[0] + ".png"), np.where(np.arange(W)[None, :] < 12, 255, 0) * np.ones((H, 1)))
    for t, name in enumerate(train):
        depth = np.where(square(t), 1.0, 2.0).astype(np.float32)
        disparity = (1.0 / depth).astype(np.float32)
        if t == 1:
            disparity = np.asfortranarray(disparity)  # numpy loads either order
        np.save(os.path.join(pre, "aligned_depth_anything_lidar/1x", name + ".npy"), disparity)
        png(os.path.join(pre, "track_anything/1x", name + ".png"), np.where(square(t), 255, 0))
    # Tracks: query frame q holds the square's 4 x 4 pixels at q plus 2 background pixels; at
    # target t the square's points move by t - q columns. Logits: visible (-5, -5); the last
    # background track is occluded at targets != q (occlusion logit +5) and the first square track
    # is uncertain at targets != q (expected-distance logit +5: conf < 0.5).
    for q in range(T):
        ys, xs = np.nonzero(square(q))
        pts = np.concatenate([np.stack([xs, ys], 1), [[0, 0], [15, 11]]]).astype(np.float32)
        for t in range(T):
            rows = np.zeros((len(pts), 4), np.float32)
            rows[:, :2] = pts
            rows[:16, 0] += t - q
            rows[:, 2:] = -5.0
            if t != q:
                rows[-1, 2] = 5.0
                rows[0, 3] = 5.0
            np.save(os.path.join(pre, "2d_tracks/1x", f"{train[q]}_{train[t]}.npy"), rows)


# COLMAP's overlay (docstring). The refined cameras differ from camera/<frame>.json on purpose, so
# that the tests see which set was read: the training frames share camera 1 (SIMPLE_RADIAL f=22,
# cx=7.0, cy=5.0, k=0.3: SoM ignores the distortion), the validation frame has camera 2 (PINHOLE
# fx=21, fy=19, cx=7.25, cy=5.75). Every training frame is rotated 10 degrees about y and
# translated by (0.2, -0.1, 0.05) COLMAP units, with scale 0.5 m per unit. images.bin lists the
# frames out of order, with one image that no split names, and 2D points (which are skipped).
COLMAP_SCALE = 0.5
COLMAP_ANGLE = np.deg2rad(10.0)


def colmap_qvec_y(angle):
    """The unit quaternion (w, x, y, z) of a rotation by `angle` about y."""
    return [np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0]


def write_colmap(root):
    sparse = os.path.join(root, "flow3d_preprocessed/colmap/sparse")
    disp_dir = os.path.join(root, "flow3d_preprocessed/aligned_depth_anything_colmap/1x")
    os.makedirs(sparse, exist_ok=True)
    os.makedirs(disp_dir, exist_ok=True)
    # cameras.bin: uint64 count; per camera int32 id, int32 model id, uint64 width, uint64 height, doubles.
    cams = [(1, 2, [22.0, 7.0, 5.0, 0.3]), (2, 1, [21.0, 19.0, 7.25, 5.75])]
    with open(os.path.join(sparse, "cameras.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(cams)))
        for cid, model, params in cams:
            f.write(struct.pack("<iiQQ", cid, model, W, H))
            f.write(struct.pack("<" + "d" * len(params), *params))
    # images.bin: uint64 count; per image int32 id, 4 + 3 doubles, int32 camera id, name + NUL,
    # uint64 point count, then (double x, double y, int64 point3D id) per point.
    images = [(7, "0_00002.png", 1), (3, "1_00001.png", 2), (5, "0_00000.png", 1), (9, "2_00000.png", 2),
              (6, "0_00001.png", 1)]
    with open(os.path.join(sparse, "images.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(images)))
        for iid, name, cid in images:
            q = colmap_qvec_y(COLMAP_ANGLE if cid == 1 else 0.0)
            t = [0.2, -0.1, 0.05] if cid == 1 else [0.0, 0.0, 0.0]
            f.write(struct.pack("<idddddddi", iid, *q, *t, cid))
            f.write(name.encode() + b"\x00")
            points = [(1.5, 2.5, -1), (3.0, 4.0, 17)]
            f.write(struct.pack("<Q", len(points)))
            for x, y, pid in points:
                f.write(struct.pack("<ddq", x, y, pid))
    np.save(os.path.join(root, "flow3d_preprocessed/colmap/scale.npy"), np.float64(COLMAP_SCALE))
    # Disparity in COLMAP units: depth_units = depth_m / scale, disparity = 1 / depth_units.
    for t in range(T):
        depth_m = np.where(square(t), 1.0, 2.0)
        np.save(os.path.join(disp_dir, f"0_{t:05d}.npy"), (COLMAP_SCALE / depth_m).astype(np.float32))


if __name__ == "__main__":
    main()
    write_colmap(os.path.join(os.path.dirname(HERE), "som_colmap"))
