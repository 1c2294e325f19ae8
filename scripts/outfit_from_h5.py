"""An outfit and a motion for `layersnet simulate` from a D-LAYERS-H5 file.

Writes OUT/<garment>.obj (v, vt, f) of every garment at one frame (default 0, the rest pose of
a file made by `layersnet generate`), and OUT/body/NNNN.obj, one per body frame, all in the
file's own units and axes. Runs in Blender's Python, which has h5py:

    blender -b --python-exit-code 1 --python scripts/outfit_from_h5.py -- FILE.h5 OUT [--frame F] [--frames N] [--subdivide GARMENT ...]

--subdivide splits every triangle of the named garment into four at its edge midpoints
(positions and UVs), about four times its vertices: a denser outfit of the same shape, e.g. for
timing a rollout on a larger mesh than the data holds.
"""
import argparse
import os
import sys

import h5py
import numpy as np


def write_obj(path, v, f, uv=None):
    with open(path, "w") as out:
        out.writelines("v %.9g %.9g %.9g\n" % tuple(p) for p in v)
        if uv is not None:  # one vt per distinct UV value, as layersnet writes them
            corners = uv.reshape(-1, 2).astype(np.float32)
            values, index = np.unique(corners, axis=0, return_inverse=True)
            out.writelines("vt %.9g %.9g\n" % tuple(t) for t in values)
            index = index.reshape(-1, 3) + 1
            out.writelines("f %d/%d %d/%d %d/%d\n" % (a + 1, ta, b + 1, tb, c + 1, tc)
                           for (a, b, c), (ta, tb, tc) in zip(f, index))
        else:
            out.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in f)


def subdivide(v, f, uv):
    """Each triangle (a, b, c) into (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)."""
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    unique, index = np.unique(edges, axis=0, return_inverse=True)
    mid = len(v) + index.reshape(3, -1).T  # (F, 3): midpoints of ab, bc, ca
    v2 = np.concatenate([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    f2 = np.concatenate([np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    uv2 = None
    if uv is not None:
        ua, ub, uc = uv[:, 0], uv[:, 1], uv[:, 2]
        uab, ubc, uca = 0.5 * (ua + ub), 0.5 * (ub + uc), 0.5 * (uc + ua)
        uv2 = np.concatenate([np.stack(t, axis=1) for t in ((ua, uab, uca), (uab, ub, ubc), (uca, ubc, uc), (uab, ubc, uca))])
    return v2, f2, uv2


def main(argv):
    p = argparse.ArgumentParser()
    p.add_argument("h5")
    p.add_argument("out")
    p.add_argument("--frame", type=int, default=0, help="frame of the garments (default 0)")
    p.add_argument("--frames", type=int, default=0, help="body frames to write (0 = all)")
    p.add_argument("--subdivide", action="append", default=[], metavar="GARMENT",
                   help="split this garment's triangles into four (repeatable)")
    a = p.parse_args(argv)
    os.makedirs(os.path.join(a.out, "body"), exist_ok=True)
    with h5py.File(a.h5, "r") as f:
        order = [n.decode() if isinstance(n, bytes) else n for n in f["garments"].attrs["order"]]
        unknown = sorted(set(a.subdivide) - set(order))
        if unknown:
            sys.exit("outfit_from_h5: --subdivide %s: %s has garments %s" % (", ".join(unknown), a.h5, ", ".join(order)))
        for name in order:
            g = f["garments"][name]
            v, faces, uv = g["vertices"][a.frame], g["faces"][:], g["uv"][:]
            if name in a.subdivide:
                v, faces, uv = subdivide(v, faces, uv.reshape(len(faces), 3, 2))
            write_obj(os.path.join(a.out, name + ".obj"), v, faces, uv)
        body = f["body"]["vertices"]
        count = body.shape[0] if a.frames <= 0 else min(a.frames, body.shape[0])
        faces = f["body"]["faces"][:]
        for t in range(count):
            write_obj(os.path.join(a.out, "body", "%04d.obj" % t), body[t], faces)
    print("outfit: %s (inner to outer), %d body frames in %s" % (", ".join(order), count, a.out))


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
