#!/usr/bin/python3
"""generate/add_pins.py on files written by the generator's own writer without pins: it gives
every garment exactly the pins the generator builds, leaves files that have pins or come from
another writer alone, and a second run changes nothing."""
import contextlib
import io
import os
import sys
import tempfile

import h5py
import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "../../generate"))
import add_pins  # noqa: E402
import outfits  # noqa: E402
from garments import SCENE_SCALE, BodyProfile  # noqa: E402
from test_garments import synthetic_body  # noqa: E402
from write_h5 import write_sequence  # noqa: E402

T = 3


def sequence(garments, generator, with_pins):
    body = synthetic_body()[::50]
    return {
        "fps": 30.0, "gravity": [0, 0, -9.8], "scale": SCENE_SCALE,
        "body": {"vertices": np.repeat(body[None], T, 0), "faces": np.array([[0, 1, 2]]),
                 "translation": np.zeros((T, 3)), "friction": 60.0},
        "garments": [{"name": g.name, "type": g.kind, "vertices": np.repeat(g.verts[None], T, 0),
                      "faces": g.faces, "uv": g.uv, "panel": g.panel, "rest": g.verts,
                      "pin": g.pin if with_pins else None,
                      "attrs": {"tension_stiffness": 50, "bending_stiffness": 50, "mass": 0.5, "self_friction": 60}}
                     for g in garments],
        "wind": {"rotation": np.tile([1.0, 0, 0, 0], (T, 1)), "strength": np.zeros(T)},
        "extra_attrs": {"generator": generator},
    }


def run(d):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = add_pins.main([d])
    return status, out.getvalue()


def pins(path):
    with h5py.File(path, "r") as f:
        return {n: (g["pin"][()] if "pin" in g else None) for n, g in f["garments"].items()}


def main():
    prof = BodyProfile(synthetic_body(), centre=(0.0, -0.03 * SCENE_SCALE), arm_x=0.25 * SCENE_SCALE)
    garments = outfits.build_outfit(prof, "skirt", "coat_sleeveless", np.random.default_rng(3))
    with tempfile.TemporaryDirectory() as d:
        old, other, pinned = (os.path.join(d, n) for n in ("old.h5", "other.h5", "pinned.h5"))
        write_sequence(old, sequence(garments, "layersnet generate (Blender cloth)", False))
        write_sequence(other, sequence(garments, "another tool", False))
        write_sequence(pinned, sequence(garments, "layersnet generate (Blender cloth)", True))
        before = os.path.getmtime(pinned)

        status, text = run(d)
        assert status == 0, text
        assert "1 files updated, 1 already had pins, 1 skipped" in text, text
        got = pins(old)
        for g in garments:
            assert got[g.name] is not None and got[g.name].dtype == np.float32, g.name
            assert np.array_equal(got[g.name], g.pin.astype(np.float32)), f"{g.name}: pins differ from the generator's"
        assert all(p is None for p in pins(other).values()), "a file of another writer was changed"
        assert os.path.getmtime(pinned) == before, "a file with pins was rewritten"

        status, text = run(d)
        assert status == 0 and "0 files updated, 2 already had pins" in text, text
        assert not [n for n in os.listdir(d) if n.endswith(".tmp")], "a temporary copy was left behind"
    print("add_pins: ok")


if __name__ == "__main__":
    main()
