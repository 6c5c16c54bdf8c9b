#!/usr/bin/python3
"""tests/fuzz/make_seeds.py — writes the crafted seeds of tests/fuzz/corpus/ (Debian's python3 and
numpy; run from anywhere). The other seeds are copies of the test fixtures (tests/data), and
files named regression-* are inputs that once crashed or exhausted a reader (kept as found).

  npz/bomb-ratio.npz       a member recording 1 GiB from 115 bytes of deflate data (more than
                           DEFLATE's 1032:1): refused before anything is inflated
  npz/bomb-header.npz      a member recording 1 MiB (within the ratio) whose .npy header declares
                           [1000000000000] float32: refused once the header is inflated
  npz/bomb-zeros.npz       a real deflate bomb, 1 MiB of zeros as float32 [262144] in ~1 KiB:
                           consistent, read (the bound is DEFLATE's ratio, not a guess)
  png/palette-trns.png     4x3 palette PNG with a tRNS chunk (comes as RGBA)
  png/grey2.png            5x2 grey PNG at 2 bits per pixel (expanded to 8)
  png/rgb16.png            2x2 RGB PNG at 16 bits (refused: 8-bit expected)
  png/regression-png_1gb_alloc-crc.png
                           png/regression-png_1gb_alloc.png (the 307-byte PNG that made stb_image
                           allocate 1 GB; its IHDR CRC was left stale, which libpng refuses first)
                           with the CRC made right, so that the pixel bound is what refuses it
"""
import io
import os
import struct
import zipfile
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def npy_bytes(a):
    b = io.BytesIO()
    np.save(b, a)
    return b.getvalue()


def npy_header_only(shape_text):
    """A version 1.0 .npy preamble + header for float32 `shape_text`, no data."""
    h = "{'descr': '<f4', 'fortran_order': False, 'shape': %s, }" % shape_text
    h += " " * (63 - (10 + len(h)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(h)) + h.encode()


def zip_member(name, data, recorded_size=None):
    """One deflated member; recorded_size overrides the uncompressed size in both headers."""
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    comp = c.compress(data) + c.flush()
    crc = zlib.crc32(data)
    usize = len(data) if recorded_size is None else recorded_size
    n = name.encode()
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0x21, crc, len(comp), usize, len(n), 0) + n + comp
    central = struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, 8, 0, 0x21, crc, len(comp), usize, len(n),
                          0, 0, 0, 0, 0, 0) + n
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 1, 1, len(central), len(local), 0)
    return local + central + end


def png(width, height, depth, colour, rows, extra=b""):
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    raw = b"".join(b"\x00" + r for r in rows)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + extra + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


def write(rel, data):
    with open(os.path.join(HERE, "corpus", rel), "wb") as f:
        f.write(data)


def main():
    # A 115-byte deflate stream (16 KiB of zeros) recorded as 1 GiB.
    write("npz/bomb-ratio.npz", zip_member("uv.npy", npy_bytes(np.zeros(4096, np.float32)), recorded_size=1 << 30))
    # Recorded size within the ratio (1 MiB from ~1 KiB), header declaring 4 TB.
    body = npy_header_only("(1000000000000,)") + bytes(1 << 20)
    write("npz/bomb-header.npz", zip_member("uv.npy", body[: 1 << 20], recorded_size=1 << 20))
    write("npz/bomb-zeros.npz", zip_member("uv.npy", npy_bytes(np.zeros(262144, np.float32))))
    plte = b"PLTE"
    palette = bytes([255, 0, 0, 0, 255, 0, 0, 0, 255])
    trns = b"\x80\xff"
    extra = (struct.pack(">I", len(palette)) + plte + palette + struct.pack(">I", zlib.crc32(plte + palette)) +
             struct.pack(">I", len(trns)) + b"tRNS" + trns + struct.pack(">I", zlib.crc32(b"tRNS" + trns)))
    write("png/palette-trns.png", png(4, 3, 8, 3, [bytes([0, 1, 2, 1])] * 3, extra))
    write("png/grey2.png", png(5, 2, 2, 0, [bytes([0b00011011, 0b11000000])] * 2))
    write("png/rgb16.png", png(2, 2, 16, 2, [bytes(12)] * 2))
    with open(os.path.join(HERE, "corpus", "png", "regression-png_1gb_alloc.png"), "rb") as f:
        b = bytearray(f.read())
    assert b[12:16] == b"IHDR"
    b[29:33] = struct.pack(">I", zlib.crc32(bytes(b[12:29])))
    write("png/regression-png_1gb_alloc-crc.png", bytes(b))


if __name__ == "__main__":
    main()
