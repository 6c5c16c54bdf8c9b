#!/usr/bin/env python3
"""scripts/failure_study.py reads the trainer's run-time signals as the trainer's rule does: a
null low-confidence share (metrics.json writes NaN as null when no node sample was observed)
keeps C-ARAP and is left out of the signal means, instead of crashing the study."""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
import failure_study as fs  # noqa: E402


def metrics(low, threshold=0.5):
    return {"signals": {"low_confidence": low, "rule_threshold": threshold}}


assert fs.picks_carap(metrics(None)), "null share: the rule keeps C-ARAP"
assert math.isnan(fs.signal(metrics(None), "low_confidence"))
assert fs.picks_carap(metrics(0.2))
assert not fs.picks_carap(metrics(0.5)), "at the threshold: plain ARAP"
assert not fs.picks_carap(metrics(0.9))
assert fs.picks_carap({"signals": {"low_confidence": 0.1}}), "older metrics without the threshold"
print("failure_study signals: ok")
