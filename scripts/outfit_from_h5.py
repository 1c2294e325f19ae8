"""An outfit and a motion for `layersnet simulate` from a D-LAYERS-H5 file.

Writes OUT/<garment>.obj (v, vt, f) of every garment at one frame (default 0, the rest pose of
a file made by `layersnet generate`), and OUT/body/NNNN.obj, one per body frame, all in the
file's own units and axes. Runs in Blender's Python, which has h5py:

    blender -b --python-exit-code 1 --python scripts/outfit_from_h5.py -- FILE.h5 OUT [--frame F] [--frames N]
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


def main(argv):
    p = argparse.ArgumentParser()
    p.add_argument("h5")
    p.add_argument("out")
    p.add_argument("--frame", type=int, default=0, help="frame of the garments (default 0)")
    p.add_argument("--frames", type=int, default=0, help="body frames to write (0 = all)")
    a = p.parse_args(argv)
    os.makedirs(os.path.join(a.out, "body"), exist_ok=True)
    with h5py.File(a.h5, "r") as f:
        order = [n.decode() if isinstance(n, bytes) else n for n in f["garments"].attrs["order"]]
        for name in order:
            g = f["garments"][name]
            write_obj(os.path.join(a.out, name + ".obj"), g["vertices"][a.frame], g["faces"][:], g["uv"][:])
        body = f["body"]["vertices"]
        count = body.shape[0] if a.frames <= 0 else min(a.frames, body.shape[0])
        faces = f["body"]["faces"][:]
        for t in range(count):
            write_obj(os.path.join(a.out, "body", "%04d.obj" % t), body[t], faces)
    print("outfit: %s (inner to outer), %d body frames in %s" % (", ".join(order), count, a.out))


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
