#!/usr/bin/env python3
"""Writes tests/data/mosca_jpeg: an overlay for tests/data/mosca_small whose training images are
JPEG files written by libjpeg-turbo's own encoder, as MoSca's iPhone folders may hold
(images/*.jpg|png, JiahuiLei/MoSca):

  images/<frame>.jpg     cjpeg -quality 95 -sample 1x1 of mosca_small's RGB image (same pixels)
  reference/<frame>.ppm  djpeg -dct int of that JPEG: the reference decoder's pixels

Copied over mosca_small (with its images/*.png removed) it is the same scene read from JPEG; the
test (tests/trainer/test_layout_mosca.cpp) compares the trainer's decode with djpeg's and with the
original pixels. Needs cjpeg and djpeg (Debian: libjpeg-turbo-progs); the outputs are checked in.
Run: /usr/bin/python3 tests/data/mosca_jpeg/make_fixture.py
"""
import importlib.util
import os
import subprocess
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def _mosca_fixture():
    spec = importlib.util.spec_from_file_location("mosca_fixture", os.path.join(HERE, "..", "mosca_small", "make_fixture.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main():
    mosca = _mosca_fixture()
    os.makedirs(os.path.join(HERE, "images"), exist_ok=True)
    os.makedirs(os.path.join(HERE, "reference"), exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for t in range(mosca.T):
            name = f"0_{t:05d}"
            rgb = mosca.rgb(t)[..., :3]
            ppm = os.path.join(tmp, name + ".ppm")
            with open(ppm, "wb") as f:
                f.write(b"P6\n%d %d\n255\n" % (mosca.W, mosca.H) + rgb.tobytes())
            jpg = os.path.join(HERE, "images", name + ".jpg")
            subprocess.run(["cjpeg", "-quality", "95", "-sample", "1x1", "-outfile", jpg, ppm], check=True)
            subprocess.run(["djpeg", "-dct", "int", "-outfile", os.path.join(HERE, "reference", name + ".ppm"), jpg],
                           check=True)


if __name__ == "__main__":
    main()
