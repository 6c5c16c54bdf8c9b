# tests/torch: pytest suite of the smg_torch extension (run by scripts/test.sh with
# PYTHONPATH=<build>/python and Debian's /usr/bin/python3).
import os
import sys

import pytest
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

torch.set_default_dtype(torch.float64)


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(1234)
