#!/usr/bin/python3
"""How far the calm twins of `scripts/predictability.sh ... calm-wind` are from the data on the
frames where the wind blows, against follow-the-body and skinning on the same frames.

Reads each EVAL folder's eval.json (made with `--replay` of the calm twins), takes every
sequence's per-frame error curve for the twin and the two baselines, keeps the frames whose
stored wind strength (the file's wind/strength, DATA/<id>.h5) is above each threshold, and prints
the summed twin error over each baseline's on those frames. Needs python3-h5py and numpy.

Usage: wind_frames.py DATA EVAL [EVAL ...] [--skip ID,ID] [--above S,S,...]
  (default --above 0,100,200; 0 keeps every scored frame)
"""
import argparse
import json
import sys

import h5py
import numpy as np


def fail(message):
    print(f"wind_frames: {message}", file=sys.stderr)
    sys.exit(1)


def curves(eval_dir):
    """{id: (first_frame, twin, follow-the-body, skinning)} per-frame error curves in mm."""
    path = f"{eval_dir}/eval.json"
    try:
        with open(path) as f:
            methods = json.load(f)["methods"]
    except (OSError, ValueError, KeyError) as e:
        fail(f"{path}: cannot read the methods of an eval report ({e})")
    by_name = {m["name"]: m for m in methods if not m["post_processed"]}
    twins = [m for m in methods if m["kind"] == "replay"]
    if not twins or "follow the body" not in by_name or "skinned to the body" not in by_name:
        fail(f"{path}: needs a --replay method and the follow-the-body and skinning baselines")
    out = {}
    for s in twins[0]["sequences"]:
        def curve(name):
            seq = next(x for x in by_name[name]["sequences"] if x["id"] == s["id"])
            return np.array(seq["error_curve_mm"])
        out[s["id"]] = (s["first_frame"], np.array(s["error_curve_mm"]), curve("follow the body"), curve("skinned to the body"))
    return out


def main(argv):
    parser = argparse.ArgumentParser(prog="wind_frames.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="the data set folder the twins were made from (DATA/<id>.h5)")
    parser.add_argument("evals", nargs="+", help="eval folders made with --replay of the calm twins")
    parser.add_argument("--skip", default="", help="sequence ids to leave out, separated by commas")
    parser.add_argument("--above", default="0,100,200",
                        help="wind strengths separated by commas; 0 keeps every scored frame")
    a = parser.parse_args(argv[1:])
    try:
        above = [float(v) for v in a.above.split(",")]
    except ValueError:
        fail(f"--above {a.above}: give strengths separated by commas, e.g. 0,100,200")
    skip = set(filter(None, a.skip.split(",")))
    data, evals = a.data, a.evals
    rows = {}
    for e in evals:
        rows.update(curves(e))
    for sid in skip:
        rows.pop(sid, None)
    strengths = {}
    for sid, (first, twin, _, _) in rows.items():
        path = f"{data}/{sid}.h5"
        try:
            with h5py.File(path, "r") as f:
                strengths[sid] = f["wind/strength"][first:first + len(twin)]
        except (OSError, KeyError) as e:
            fail(f"{path}: cannot read wind/strength ({e})")
    print(f"{len(rows)} sequences: {' '.join(sorted(rows))}")
    for threshold in above:
        twin_sum = follow_sum = skin_sum = 0.0
        frames = 0
        for sid, (_, twin, follow, skin) in rows.items():
            keep = strengths[sid] > threshold if threshold > 0 else np.ones(len(twin), bool)
            twin_sum += twin[keep].sum()
            follow_sum += follow[keep].sum()
            skin_sum += skin[keep].sum()
            frames += int(keep.sum())
        label = "every scored frame" if threshold <= 0 else f"strength above {threshold:g}"
        if frames == 0:
            print(f"{label}: no frame")
            continue
        print(f"{label}: {frames} frames, calm twin / follow the body {twin_sum / follow_sum:.3f}, "
              f"calm twin / skinning {twin_sum / skin_sum:.3f}")


if __name__ == "__main__":
    main(sys.argv)
