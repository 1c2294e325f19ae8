#!/usr/bin/python3
"""Exit 0 iff two D-LAYERS-H5 files hold identical datasets and identical attributes,
ignoring the attributes that are wall-clock timings (q_blender_s_per_frame)."""
import sys

import h5py
import numpy as np

TIMING = {"q_blender_s_per_frame"}


def items(f):
    out = {}
    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            out["D:" + name] = obj[()]
        for k, v in obj.attrs.items():
            if k not in TIMING:
                out[f"A:{name}@{k}"] = v
    for k, v in f.attrs.items():
        if k not in TIMING:
            out["A:/@" + k] = v
    f.visititems(visit)
    return out


a, b = (items(h5py.File(p, "r")) for p in sys.argv[1:3])
bad = sorted(set(a) ^ set(b))
for k in sorted(set(a) & set(b)):
    x, y = np.asarray(a[k]), np.asarray(b[k])
    if x.shape != y.shape or not np.array_equal(x, y):
        bad.append(k)
print("differences:", bad if bad else "none")
sys.exit(1 if bad else 0)
