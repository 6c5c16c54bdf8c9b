#!/usr/bin/python3
"""Random arrays of several sizes and dtypes in one np.savez_compressed archive, for
tests/trainer/test_numpy_files.cpp (run at test time where numpy is installed; nothing is
checked in).

    /usr/bin/python3 tests/data/numpy/make_random.py OUTDIR SEED

Writes OUTDIR/random.npz and, for every member NAME, OUTDIR/NAME.bin: the array's bytes in C
order (ndarray.tobytes(order="C"), numpy's own serialisation), and OUTDIR/manifest.txt with one
line per member: "NAME DTYPE DIM...". Members whose name starts with "fortran_" are stored in
Fortran order; their .bin is still C order.
"""
import os
import sys

import numpy as np


def main():
    out, seed = sys.argv[1], int(sys.argv[2])
    os.makedirs(out, exist_ok=True)
    rng = np.random.default_rng(seed)
    arrays = {}
    for n in (1, 999, 70001, 100000):
        arrays[f"f32_{n}"] = rng.standard_normal(n).astype(np.float32)
        arrays[f"f64_{n}"] = rng.standard_normal(n)
        arrays[f"b1_{n}"] = rng.random(n) < 0.3
        arrays[f"i32_{n}"] = rng.integers(-2**31, 2**31, n, dtype=np.int32)
        arrays[f"i64_{n}"] = rng.integers(-2**62, 2**62, n, dtype=np.int64)
        # Compressible: small integers as float32 (long matches, many Huffman blocks).
        arrays[f"steps_{n}"] = np.round(rng.random(n) * 4).astype(np.float32)
    arrays["u8_3d"] = rng.integers(0, 256, (40, 30, 3), dtype=np.uint8)
    arrays["f16_2d"] = rng.standard_normal((64, 48)).astype(np.float16)
    arrays["fortran_f32_3d"] = np.asfortranarray(rng.standard_normal((30, 41, 3)).astype(np.float32))
    arrays["fortran_b1_2d"] = np.asfortranarray(rng.random((123, 77)) < 0.5)
    arrays["fortran_i64_4d"] = np.asfortranarray(rng.integers(-1000, 1000, (5, 6, 7, 8), dtype=np.int64))
    np.savez_compressed(os.path.join(out, "random.npz"), **arrays)
    with open(os.path.join(out, "manifest.txt"), "w") as m:
        for name, a in arrays.items():
            with open(os.path.join(out, name + ".bin"), "wb") as f:
                f.write(a.tobytes(order="C"))
            m.write(" ".join([name, a.dtype.str] + [str(d) for d in a.shape]) + "\n")


if __name__ == "__main__":
    main()
