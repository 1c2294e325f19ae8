#!/usr/bin/python3
"""How much of a frame's garment acceleration simple local features explain.

Usage: /usr/bin/python3 scripts/one_step_baseline.py DATASET [TRAIN_SEQUENCES=12]

For every garment vertex and moving frame t (after the ramp), the target is the acceleration
x(t+1) - 2 x(t) + x(t-1) (what constant velocity gets wrong in one step). A least-squares
linear model is fitted on the first TRAIN_SEQUENCES training sequences over local features:
the vertex's velocity and previous acceleration, its nearest body vertex's velocity at t and
t+1 and acceleration, the offset to it, contact-gated copies, and the edge-spring force,
Laplacian and velocity Laplacian of the garment mesh. Prints the one-step RMS error in mm of
constant velocity and of the linear model on 4 training sequences and on the test split: a
learned simulator's one-step error should sit well below the linear model's.
Needs python3-numpy and python3-h5py (Debian).
"""
import glob
import json
import os
import sys

import h5py
import numpy as np


def edges_of(faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, 1), axis=0)


def nearest(points, body):
    """Index and distance of each point's nearest body vertex (chunked, exact)."""
    idx = np.empty(len(points), dtype=np.int64)
    dist = np.empty(len(points))
    bb = (body ** 2).sum(1)
    for a in range(0, len(points), 512):
        p = points[a:a + 512]
        d2 = (p ** 2).sum(1)[:, None] - 2 * p @ body.T + bb[None, :]
        i = d2.argmin(1)
        idx[a:a + 512] = i
        dist[a:a + 512] = np.sqrt(np.maximum(d2[np.arange(len(p)), i], 0))
    return idx, dist


def features(path):
    f = h5py.File(path, "r")
    body = f["body/vertices"][:].astype(np.float64)
    start = int(f.attrs.get("rest_frames", 0)) + int(f.attrs.get("ramp_frames", 0))
    scale = float(f.attrs.get("scale", 10.0))
    xs, ys = [], []
    for name in f["garments"]:
        g = f["garments"][name]
        x = g["vertices"][:].astype(np.float64)
        n = x.shape[1]
        e = edges_of(g["faces"][:])
        rest = g["rest"][:].astype(np.float64)
        l0 = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
        deg = np.maximum(np.bincount(e.ravel(), minlength=n), 1)[:, None]
        for t in range(max(start, 2), x.shape[0] - 1):
            i, d = nearest(x[t], body[t])
            v = x[t] - x[t - 1]
            a_prev = x[t] - 2 * x[t - 1] + x[t - 2]
            bv1 = body[t + 1][i] - body[t][i]
            bv0 = body[t][i] - body[t - 1][i]
            near = (d < 0.3)[:, None]
            ev = x[t][e[:, 1]] - x[t][e[:, 0]]
            length = np.linalg.norm(ev, axis=1)
            spring = ((length - l0) / np.maximum(length, 1e-9))[:, None] * ev
            fs = np.zeros((n, 3)); np.add.at(fs, e[:, 0], spring); np.add.at(fs, e[:, 1], -spring)
            lap = np.zeros((n, 3)); np.add.at(lap, e[:, 0], ev); np.add.at(lap, e[:, 1], -ev)
            dv = v[e[:, 1]] - v[e[:, 0]]
            lv = np.zeros((n, 3)); np.add.at(lv, e[:, 0], dv); np.add.at(lv, e[:, 1], -dv)
            xs.append(np.concatenate([v, a_prev, bv1, bv0, bv1 - bv0, x[t] - body[t][i], near * (bv1 - v),
                                      near * bv1, near * v, fs, lap / deg, lv / deg, np.ones((n, 1))], 1))
            ys.append(x[t + 1] - 2 * x[t] + x[t - 1])
    return np.concatenate(xs), np.concatenate(ys), 1000.0 / scale


def main():
    root = sys.argv[1]
    n_fit = int(sys.argv[2]) if len(sys.argv) > 2 else 12
    splits = json.load(open(os.path.join(root, "dataset.json")))["splits"]
    path = lambda s: os.path.join(root, s + ".h5")
    fit = [features(path(s)) for s in splits["train"][:n_fit]]
    w = np.linalg.lstsq(np.concatenate([f[0] for f in fit]), np.concatenate([f[1] for f in fit]), rcond=None)[0]
    print(f"linear model fitted on {n_fit} training sequences, {sum(len(f[1]) for f in fit)} vertex-frames")
    print("| split | sequences | constant velocity mm (RMS) | linear model mm (RMS) | ratio |")
    print("|---|---|---|---|---|")
    for split, ids in (("train", splits["train"][:4]), ("test", splits["test"])):
        cv, lin = [], []
        for s in ids:
            xf, yf, mm = features(path(s))
            cv.append((yf ** 2).sum(1) * mm ** 2)
            lin.append(((yf - xf @ w) ** 2).sum(1) * mm ** 2)
        cv, lin = np.sqrt(np.concatenate(cv).mean()), np.sqrt(np.concatenate(lin).mean())
        print(f"| {split} | {len(ids)} | {cv:.1f} | {lin:.1f} | {lin / cv:.2f} |")


if __name__ == "__main__":
    main()
