#!/usr/bin/python3
"""Adds /garments/<name>/pin to sequences that `layersnet generate` wrote before it stored pins.

    /usr/bin/python3 generate/add_pins.py DIR [DIR ...]

Every garment the generator builds pins exactly its top ring, so the weights follow from
/rest (garments.top_ring_pin): 1 on the ring at the garment's highest rest coordinate along
the file's up axis, else 0. Files that have pins or come from another generator are left
alone. A file is changed on a copy that is then renamed over it, so a reader holding it
open (a training run) keeps reading a consistent file, and an interrupted run leaves the
original. Exit status 1 when a generated file could not be given pins.
"""
import glob
import os
import shutil
import sys

import h5py
import numpy as np

from garments import top_ring_pin

GENERATOR = "layersnet generate"


def _text(v):
    v = v.item() if isinstance(v, np.ndarray) else v
    return v.decode() if isinstance(v, bytes) else v


def plan(f, path):
    """('add', {garment: pin}), ('have' / 'other', None) or ('skip' / 'fail', message)."""
    gen = _text(f.attrs.get("generator", ""))
    if _text(f.attrs.get("format", "")) != "dlayers-h5":
        return "other", None  # stats.h5 and the like: not a sequence
    if not str(gen).startswith(GENERATOR):
        what = f"generator '{gen}'" if gen else f"format '{_text(f.attrs.get('format', ''))}', no generator"
        return "skip", f"add_pins: {path}: skipped, not written by {GENERATOR} ({what})"
    up = _text(f.attrs.get("up_axis", ""))
    if up not in ("z", "y"):
        return "fail", f"add_pins: {path}: up_axis '{up}' is not 'z' or 'y'; file skipped"
    pins = {}
    for name, g in f["garments"].items():
        if "pin" in g:
            continue
        if "rest" not in g:
            return "fail", f"add_pins: {path}: garment '{name}' has no rest shape to find its top ring; file skipped"
        n = g["vertices"].shape[1]
        pin, why = top_ring_pin(g["rest"][()], g["faces"][()], 2 if up == "z" else 1)
        if why is None and len(pin) != n:
            why = f"rest has {len(pin)} vertices, the garment {n}"
        if why is not None:
            return "fail", f"add_pins: {path}: garment '{name}': {why}; file skipped"
        pins[name] = pin
    return ("add", pins) if pins else ("have", None)


def add_pins(path, pins):
    tmp = path + ".pins.tmp"
    shutil.copy2(path, tmp)
    try:
        with h5py.File(tmp, "r+") as f:
            for name, pin in pins.items():
                f["garments"][name].create_dataset("pin", data=pin.astype(np.float32))
        os.replace(tmp, path)
    except BaseException:
        os.remove(tmp)
        raise


def main(dirs):
    if not dirs:
        print(__doc__.strip())
        return 2
    updated = have = skipped = failed = 0
    rings = set()
    for d in dirs:
        if not os.path.isdir(d):
            print(f"add_pins: {d}: not a directory")
            return 2
        for path in sorted(glob.glob(os.path.join(d, "*.h5"))):
            with h5py.File(path, "r") as f:
                action, what = plan(f, path)
            if action == "add":
                add_pins(path, what)
                rings.update(int(p.sum()) for p in what.values())
                updated += 1
            elif action == "have":
                have += 1
            elif action == "other":
                continue
            else:
                print(what)
                skipped += 1
                failed += action == "fail"
    ring_text = f"; top rings of {', '.join(map(str, sorted(rings)))} vertices" if rings else ""
    print(f"add_pins: {updated} files updated, {have} already had pins, {skipped} skipped "
          f"({failed} of them generated files that could not be given pins){ring_text}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
