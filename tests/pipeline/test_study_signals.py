#!/usr/bin/env python3
"""scripts/failure_study.py reads the trainer's run-time signals without crashing on a null one:
metrics.json writes NaN as null when no node sample was observed; the study reads it as NaN and
leaves it out of the signal means."""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
import failure_study as fs  # noqa: E402


def metrics(low):
    return {"signals": {"low_confidence": low}}


assert math.isnan(fs.signal(metrics(None), "low_confidence")), "null: NaN"
assert fs.signal(metrics(0.25), "low_confidence") == 0.25
assert math.isnan(fs.signal({"signals": {}}, "low_confidence")), "a signal the trainer did not write: NaN"
print("failure_study signals: ok")
