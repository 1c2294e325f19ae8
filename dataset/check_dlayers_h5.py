#!/usr/bin/python3
"""Strict validator of D-LAYERS-H5 files and data-set folders (docs/dlayers-h5.md), with h5py.

    /usr/bin/python3 dataset/check_dlayers_h5.py PATH [PATH ...]

PATH is a sequence file or a data-set folder (its dataset.json and every listed file).
Every problem is printed as "<file>: <object path>: <what is wrong>"; the exit status is 1
when there is any, else 0. It is independent of the C++ reader, so the two check each other.
"""
import json
import os
import sys

import h5py
import numpy as np

ALLOWED_FILTERS = {"gzip", "shuffle"}
GARMENT_ATTRS = ("tension_stiffness", "bending_stiffness", "mass", "self_friction")


class Problems:
    def __init__(self, path):
        self.path, self.items = path, []

    def add(self, obj, what):
        self.items.append(f"{self.path}: {obj}: {what}")


def is_string(v):
    return isinstance(v, (str, bytes)) or (isinstance(v, np.ndarray) and v.dtype.kind in "SOU" and v.shape == ())


def text(v):
    v = v.item() if isinstance(v, np.ndarray) else v
    return v.decode() if isinstance(v, bytes) else v


def attr(p, obj, name, kind):
    """The attribute's value if it has the kind ('str', 'int', 'float', 'float3'), else None."""
    if name not in obj.attrs:
        p.add(obj.name, f"missing attribute '{name}'")
        return None
    v = obj.attrs[name]
    if kind == "str":
        if not is_string(v):
            p.add(obj.name, f"attribute '{name}' must be a string")
            return None
        return text(v)
    a = np.asarray(v)
    if kind == "int":
        if a.shape != () or a.dtype.kind not in "iu" or a.dtype == np.bool_:
            p.add(obj.name, f"attribute '{name}' must be an integer")
            return None
        return int(a)
    if a.dtype.kind != "f":
        p.add(obj.name, f"attribute '{name}' must be a float")
        return None
    if kind == "float3":
        if a.shape != (3,):
            p.add(obj.name, f"attribute '{name}' must hold 3 floats")
            return None
    elif a.shape != ():
        p.add(obj.name, f"attribute '{name}' must be a float")
        return None
    if not np.all(np.isfinite(a)):
        p.add(obj.name, f"attribute '{name}' is not finite")
        return None
    with np.errstate(over="ignore"):
        if not np.all(np.isfinite(a.astype(np.float32))):
            p.add(obj.name, f"attribute '{name}' is not finite in float32")
            return None
    return a


def property_attr(p, obj, name):
    """A physical property (friction, stiffness, mass): a float, finite in float32, >= 0."""
    a = attr(p, obj, name, "float")
    if a is not None and a < 0:
        p.add(obj.name, f"attribute '{name}' is negative")


MAX_SCENE_COORDINATE = 1e4  # scene units: 1 km at the x10 convention


def dataset(p, parent, name, kind, shape, coordinates=False):
    """The array of dataset parent/name if its dtype kind ('f' or 'i') and shape match; shape
    entries None match any size; coordinates: every |value| <= MAX_SCENE_COORDINATE. Returns
    None (and records why) otherwise."""
    where = f"{parent.name.rstrip('/')}/{name}"
    if name not in parent:
        p.add(where, "missing dataset")
        return None
    d = parent[name]
    if not isinstance(d, h5py.Dataset):
        p.add(where, "must be a dataset")
        return None
    for f in _filters(d):
        if f not in ALLOWED_FILTERS:
            p.add(where, f"filter '{f}' is not allowed (gzip and shuffle only)")
            return None
    dt = d.dtype
    ok = dt in (np.float32, np.float64) if kind == "f" else dt in (np.int32, np.int64)
    if not ok:
        p.add(where, f"dtype {dt} is not allowed ({'float32/float64' if kind == 'f' else 'int32/int64'})")
        return None
    if len(d.shape) != len(shape) or any(s is not None and s != n for s, n in zip(shape, d.shape)):
        p.add(where, f"shape {d.shape} does not match {tuple('*' if s is None else s for s in shape)}")
        return None
    a = d[()]
    if kind == "f" and not np.all(np.isfinite(a)):
        p.add(where, "holds non-finite values")
        return None
    with np.errstate(over="ignore"):
        if kind == "f" and not np.all(np.isfinite(a.astype(np.float32))):
            p.add(where, "holds values that are not finite in float32")
            return None
    if coordinates and a.size and np.abs(a).max() > MAX_SCENE_COORDINATE:
        p.add(where, f"holds coordinates beyond the scene extent +-{MAX_SCENE_COORDINATE:g} units")
        return None
    return a


def _filters(d):
    out = []
    if d.compression:
        out.append(d.compression)
    if d.shuffle:
        out.append("shuffle")
    if d.fletcher32:
        out.append("fletcher32")
    if d.scaleoffset is not None:
        out.append("scaleoffset")
    return out


def check_faces(p, where, faces, n, what="faces"):
    if faces is None:
        return False
    if len(faces) == 0:
        p.add(where, f"has no {what}")
        return False
    if faces.min() < 0 or faces.max() >= n:
        p.add(where, f"face index out of range [0, {n})")
        return False
    return True


def check_sequence(path):
    p = Problems(path)
    try:
        f = h5py.File(path, "r")
    except Exception as e:  # noqa: BLE001 - any h5py failure means the file is unreadable
        p.add("/", f"cannot be opened as HDF5 ({e})")
        return p.items
    with f:
        fmt = attr(p, f, "format", "str")
        if fmt is not None and fmt != "dlayers-h5":
            p.add("/", f"'format' is '{fmt}', expected 'dlayers-h5'")
        version = attr(p, f, "version", "int")
        if version is not None and version != 1:
            p.add("/", f"version {version} is not 1")
        fps = attr(p, f, "fps", "float")
        if fps is not None and not fps > 0:
            p.add("/", "'fps' must be > 0")
        up = attr(p, f, "up_axis", "str")
        if up is not None and up not in ("z", "y"):
            p.add("/", f"'up_axis' is '{up}', expected 'z' or 'y'")
        g = attr(p, f, "gravity", "float3")
        if g is not None and up in ("z", "y"):
            axis = 2 if up == "z" else 1
            if g[axis] >= 0 or np.any(np.delete(g, axis) != 0):
                p.add("/", f"'gravity' {g.tolist()} does not point down the up axis '{up}'")
        scale = attr(p, f, "scale", "float")
        if scale is not None and not scale > 0:
            p.add("/", "'scale' must be > 0")
        # Optional: how the generator drove Blender (read by the physics loss).
        if "wind_field_factor" in f.attrs:
            factor = attr(p, f, "wind_field_factor", "float")
            if factor is not None and not (np.isfinite(factor) and factor >= 0):
                p.add("/", f"'wind_field_factor' {factor} must be finite and >= 0")
        if "stiffness_groups" in f.attrs:
            rule = attr(p, f, "stiffness_groups", "str")
            if rule is not None and rule not in ("per_layer", "outer_max"):
                p.add("/", f"'stiffness_groups' is '{rule}', expected 'per_layer' or 'outer_max'")
        T = check_body(p, f)
        check_garments(p, f, T)
        check_wind(p, f, T)
    return p.items


def check_body(p, f):
    if "body" not in f or not isinstance(f["body"], h5py.Group):
        p.add("/body", "missing group")
        return None
    b = f["body"]
    verts = dataset(p, b, "vertices", "f", (None, None, 3), coordinates=True)
    faces = dataset(p, b, "faces", "i", (None, 3))
    property_attr(p, b, "friction")
    T = None
    if verts is not None:
        T = verts.shape[0]
        if T < 3:
            p.add("/body/vertices", f"{T} frames; at least 3 are needed")
        if check_faces(p, "/body/faces", faces, verts.shape[1]) and T >= 1:
            x = verts[0].astype(np.float64)
            a, bb, c = (x[faces[:, k]] for k in range(3))
            if np.einsum("ij,ij->i", a, np.cross(bb, c)).sum() < 0:
                p.add("/body/faces", "faces wind clockwise seen from outside (normals point into the body)")
    if "translation" in b:
        tr = dataset(p, b, "translation", "f", (None, 3), coordinates=True)
        if tr is not None and T is not None and tr.shape[0] != T:
            p.add("/body/translation", f"{tr.shape[0]} frames, the body has {T}")
    return T


def check_garments(p, f, T):
    if "garments" not in f or not isinstance(f["garments"], h5py.Group):
        p.add("/garments", "missing group")
        return
    gs = f["garments"]
    order = None
    if "order" not in gs.attrs:
        p.add("/garments", "missing attribute 'order'")
    else:
        o = gs.attrs["order"]
        if not (isinstance(o, np.ndarray) and o.ndim == 1 and o.dtype.kind in "SOU"):
            p.add("/garments", "'order' must be a 1-D array of strings")
        else:
            order = [text(x) for x in o]
    members = list(gs.keys())
    for m in members:
        if not isinstance(gs[m], h5py.Group):
            p.add(f"/garments/{m}", "must be a group (one per garment)")
    groups = [m for m in members if isinstance(gs[m], h5py.Group)]
    if not groups:
        p.add("/garments", "holds no garment")
    if order is not None:
        if len(set(order)) != len(order):
            p.add("/garments", "'order' names a garment twice")
        for name in order:
            if name not in groups:
                p.add("/garments", f"'order' names '{name}', which is not a garment group")
        for name in groups:
            if name not in order:
                p.add("/garments", f"garment '{name}' is missing from 'order'")
    for name in groups:
        check_garment(p, gs[name], T)


def check_garment(p, g, T):
    where = g.name
    verts = dataset(p, g, "vertices", "f", (None, None, 3), coordinates=True)
    faces = dataset(p, g, "faces", "i", (None, 3))
    n = None
    if verts is not None:
        n = verts.shape[1]
        if n == 0:
            p.add(f"{where}/vertices", "has no vertices")
        if T is not None and verts.shape[0] != T:
            p.add(f"{where}/vertices", f"{verts.shape[0]} frames, the body has {T}")
    F = len(faces) if faces is not None else None
    if n:
        check_faces(p, f"{where}/faces", faces, n)
    uv = dataset(p, g, "uv", "f", (F, 3, 2))
    panel = dataset(p, g, "panel", "i", (F,))
    del uv
    if panel is not None and len(panel) and panel.min() < 0:
        p.add(f"{where}/panel", "negative panel index")
    if "rest" in g:
        dataset(p, g, "rest", "f", (n, 3), coordinates=True)
    if "pin" in g:
        pin = dataset(p, g, "pin", "f", (n,))
        if pin is not None and len(pin) and (pin.min() < 0 or pin.max() > 1):
            p.add(f"{where}/pin", f"weights must lie in [0, 1] (found {pin.min():g} to {pin.max():g})")
    t = attr(p, g, "type", "str")
    if t is not None and not t:
        p.add(where, "attribute 'type' is empty")
    for a in GARMENT_ATTRS:
        property_attr(p, g, a)


def check_wind(p, f, T):
    if "wind" not in f:
        return
    w = f["wind"]
    if not isinstance(w, h5py.Group):
        p.add("/wind", "must be a group")
        return
    rot = dataset(p, w, "rotation", "f", (T, 4))
    dataset(p, w, "strength", "f", (T,))
    if rot is not None and np.any(np.abs(np.linalg.norm(rot, axis=1) - 1) > 1e-3):
        p.add("/wind/rotation", "quaternions must have unit length")


def check_folder(root):
    path = os.path.join(root, "dataset.json")
    p = Problems(path)
    try:
        with open(path) as fh:
            m = json.load(fh)
    except (OSError, ValueError) as e:
        p.add("/", f"cannot be read as JSON ({e})")
        return p.items
    if m.get("format") != "dlayers-h5":
        p.add("/format", "must be 'dlayers-h5'")
    if type(m.get("version")) is not int or m.get("version") != 1:
        p.add("/version", "must be the integer 1")
    if not isinstance(m.get("source"), str):
        p.add("/source", "missing")
    splits = m.get("splits")
    if not isinstance(splits, dict):
        p.add("/splits", "missing or not an object")
        return p.items
    seen, problems = set(), list(p.items)
    for split, ids in splits.items():
        if split not in ("train", "val", "test"):
            problems.append(f"{path}: /splits/{split}: unknown split")
            continue
        for sid in ids if isinstance(ids, list) else []:
            if not isinstance(sid, str) or not sid or "/" in sid:
                problems.append(f"{path}: /splits/{split}: invalid sequence id {sid!r}")
                continue
            if sid in seen:
                problems.append(f"{path}: /splits/{split}: '{sid}' is listed twice")
            seen.add(sid)
            problems += check_sequence(os.path.join(root, sid + ".h5"))
    return problems


def main(paths):
    if not paths:
        print(__doc__.strip())
        return 2
    problems = []
    for path in paths:
        problems += check_folder(path) if os.path.isdir(path) else check_sequence(path)
    for line in problems:
        print(line)
    print(f"check_dlayers_h5: {len(problems)} problems in {len(paths)} path(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
