#!/usr/bin/python3
"""Writes the numpy fixtures of tests/data/numpy/ with numpy's own writers (issue 23).

    /usr/bin/python3 tests/data/numpy/make_fixtures.py [OUTDIR]   # default: this folder

Every array is a formula of its C-order flat index k (base = np.arange(n).reshape(shape)), so the
C++ tests (tests/trainer/test_numpy_files.cpp, tests/examples/test_npy.cpp) recompute each value
independently of any reader. Keep the two in step: a change here needs the same change there.

- compressed.npz  np.savez_compressed (deflate members, numpy's ZIP64 local extra field)
- stored.npz      np.savez (stored members)
- streamed.npz    np.savez_compressed into a stream that cannot seek (a pipe): Python's zipfile
                  then sets flag bit 3 and writes each member's sizes and CRC-32 in a data
                  descriptor after its data (zero in the local header)
- fortran_*.npy   np.save of np.asfortranarray(...) ('fortran_order': True), every dtype the
                  readers accept, ranks 2 to 4
"""
import os
import sys

import numpy as np


def base(shape):
    return np.arange(int(np.prod(shape))).reshape(shape)


# name -> (formula of base, dtype, shape); the C++ tests hold the same table.
ARRAYS = {
    "f32": (lambda b: b * 0.5, np.float32, (4, 3, 2)),
    "f64": (lambda b: (b - 17) / 8.0, np.float64, (5, 7)),
    "b1": (lambda b: b % 7 == 3, np.bool_, (6, 10)),
    "i32": (lambda b: b * -3 + 5, np.int32, (17,)),
    "i64": (lambda b: b * 1000000007, np.int64, (3, 4)),
    "empty": (lambda b: b * 1.0, np.float32, (0, 3)),
    "scalar": (lambda b: b + 42, np.int64, ()),
    # The member: 3728 bytes uncompressed (128 header + 3600 bool), compresses well.
    "visible": (lambda b: (b * 7 + (b // 100) * 3) % 11 < 6, np.bool_, (36, 100)),
    # The top 20 bits of Knuth's multiplicative hash of k: 96000 bytes that deflate only to about
    # 74000 (> 64 KiB compressed, Huffman-coded blocks across the 32 KiB window).
    "big": (lambda b: ((b.astype(np.uint64) * 2654435761) % 4294967296) >> 12, np.int32, (24000,)),
}

FORTRAN = {
    "fortran_f64_2d": (lambda b: b * 0.25 - 3, np.float64, (4, 5)),
    "fortran_f32_3d": (lambda b: b * 1.5, np.float32, (2, 3, 4)),
    "fortran_bool_2d": (lambda b: b % 3 == 1, np.bool_, (3, 5)),
    "fortran_bool_3d": (lambda b: b % 4 == 2, np.bool_, (2, 3, 4)),
    "fortran_i32_3d": (lambda b: b * -7 + 11, np.int32, (3, 2, 4)),
    "fortran_i64_2d": (lambda b: b * 10**12, np.int64, (2, 7)),
    "fortran_u8_4d": (lambda b: b % 251, np.uint8, (2, 3, 2, 2)),
    "fortran_f16_2d": (lambda b: b * 0.5, np.float16, (3, 4)),
}


class Unseekable:
    """A write-only stream without tell/seek, like a pipe."""

    def __init__(self, f):
        self.f = f

    def write(self, b):
        return self.f.write(b)

    def flush(self):
        self.f.flush()

    def read(self, n=-1):  # numpy takes an object with read() for a file, not a path
        raise OSError("write-only stream")


def make(table, name):
    f, dtype, shape = table[name]
    return np.asarray(f(base(shape)), dtype=dtype)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
    os.makedirs(out, exist_ok=True)
    arrays = {k: make(ARRAYS, k) for k in ARRAYS}
    arrays["fortran"] = np.asfortranarray(make(FORTRAN, "fortran_f32_3d"))
    np.savez_compressed(os.path.join(out, "compressed.npz"), **arrays)
    np.savez(os.path.join(out, "stored.npz"), f64=arrays["f64"], b1=arrays["b1"], i32=arrays["i32"],
             fortran=np.asfortranarray(make(FORTRAN, "fortran_i32_3d")))
    with open(os.path.join(out, "streamed.npz"), "wb") as f:
        np.savez_compressed(Unseekable(f), f64=arrays["f64"], visible=arrays["visible"], i64=arrays["i64"])
    for k in FORTRAN:
        a = np.asfortranarray(make(FORTRAN, k))
        assert a.flags.f_contiguous and not a.flags.c_contiguous
        np.save(os.path.join(out, k + ".npy"), a)


if __name__ == "__main__":
    main()
