# The data's side of the stress bound (eval/stress.h): for every garment of every sequence, the
# largest Euclidean extent max_{u,v} |x_u - x_v| over frames (after the rest frames), divided by
# the rest mesh's graph diameter D_g. The bound allows 1.2 (kStretchAllowance).
# Usage: /usr/bin/python3 scripts/garment_extent.py data/default/0*.h5   (needs python3-h5py)
import sys

import h5py
import numpy as np

worst_all = 0
for path in sys.argv[1:]:
    f = h5py.File(path, 'r'); worst = 0; first = int(f.attrs.get('rest_frames', 0))
    for name, g in f['garments'].items():
        rest = g['rest'][...]; faces = g['faces'][...]
        a = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]]); b = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
        w = np.linalg.norm(rest[a] - rest[b], axis=1); n = len(rest)
        D = np.full((n, n), np.inf); np.fill_diagonal(D, 0)
        D[a, b] = np.minimum(D[a, b], w); D[b, a] = np.minimum(D[b, a], w)
        for k in range(n): D = np.minimum(D, D[:, k:k + 1] + D[k:k + 1, :])  # Floyd-Warshall
        mask = np.isfinite(D) & (D > 0)
        X = g['vertices'][...]
        for t in range(first, X.shape[0]):
            E = np.linalg.norm(X[t][:, None, :] - X[t][None, :, :], axis=2)
            worst = max(worst, float(E.max() / D[np.isfinite(D)].max()))
    print(path, round(worst, 3)); worst_all = max(worst_all, worst)
print('max', round(worst_all, 3))
