#!/usr/bin/python3
"""Converts the published D-LAYERS release (ICCV 2023) to D-LAYERS-H5 (dlayers-h5.md).

Usage:
  /usr/bin/python3 generate/convert_dlayers.py --root D-LAYERS/data --smpl-dir SMPL/model --out OUT
      [--sequences 00396,00397]

--root holds train_val_test.json and one folder per sequence (meta.json, <garment>.pkl,
uv_<garment>.pkl); human.motion_path in meta.json is relative to --root's parent's 'data'
layout as in the official code (tried relative to --root and to its parent).
--smpl-dir holds the user's SMPL model files model_f / model_m as .pkl (the official ones;
their chumpy arrays are read without chumpy) or .npz with the same keys
(v_template, shapedirs, posedirs, J_regressor, weights, kintree_table, f).

Per sequence (facts from the official data-loading code):
- T = seq_end - seq_start; garment frame f <-> motion frame f + seq_start (the correct
  alignment; the official preprocessing adds seq_start twice, harmless iff it is 0).
- body = human.scale x SMPL(poses, betas, trans) with pose blend shapes, SMPL faces.
- garments in meta order (inner -> outer); faces, UV corners and panel ids from the UV
  pickle's groups (dict order = panel order; polygons fan-triangulated).
- wind: pivots relative to frame_start - human.frame_start, piecewise constant; before the
  first pivot strength 0 (identity rotation, since the file needs unit quaternions).
"""
import argparse
import json
import os
import pickle
import sys
import types

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from write_h5 import write_sequence  # noqa: E402


class _ChumpyStub:
    """Unpickles chumpy arrays (SMPL's .pkl) without chumpy: keeps the state, exposes .r."""

    def __init__(self, *a, **k):
        pass

    def __setstate__(self, state):
        self.__dict__.update(state if isinstance(state, dict) else {"x": state})

    @property
    def r(self):
        return np.asarray(self.__dict__.get("x"))


def _install_chumpy_stub():
    if "chumpy" in sys.modules:
        return
    mod = types.ModuleType("chumpy")
    for sub in ("ch", "ch_ops", "reordering", "utils", "linalg", "logic"):
        m = types.ModuleType("chumpy." + sub)
        m.__getattr__ = lambda name: _ChumpyStub
        sys.modules["chumpy." + sub] = m
    mod.__getattr__ = lambda name: _ChumpyStub
    sys.modules["chumpy"] = mod


def load_smpl(path):
    """dict of numpy arrays: v_template (V,3), shapedirs (V,3,S), posedirs (V,3,207),
    J_regressor (24,V), weights (V,24), kintree_table (2,24), f (F,3)."""
    if path.endswith(".npz"):
        raw = dict(np.load(path, allow_pickle=False))
    else:
        _install_chumpy_stub()
        with open(path, "rb") as fh:
            raw = pickle.load(fh, encoding="latin1")
    out = {}
    for k in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f"):
        if k not in raw:
            raise SystemExit(f"convert_dlayers.py: {path}: SMPL key '{k}' missing (use the official SMPL model)")
        v = raw[k]
        if isinstance(v, _ChumpyStub):
            v = v.r
        elif hasattr(v, "toarray"):   # scipy sparse J_regressor
            v = v.toarray()
        out[k] = np.asarray(v)
    return out


def _rodrigues(r):
    """(K, 3) axis-angle -> (K, 3, 3)."""
    theta = np.linalg.norm(r, axis=1, keepdims=True)
    k = r / np.maximum(theta, 1e-12)
    K = np.zeros((len(r), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, :, None], np.cos(theta)[:, :, None]
    return np.eye(3)[None] + s * K + (1 - c) * K @ K


def smpl_vertices(model, pose, betas, trans):
    """Standard SMPL: pose (72,), betas (<=S,), trans (3,) -> (V, 3) metres."""
    nb = min(len(betas), model["shapedirs"].shape[-1])
    v_shaped = model["v_template"] + model["shapedirs"][..., :nb] @ betas[:nb]
    J = model["J_regressor"] @ v_shaped
    R = _rodrigues(pose.reshape(-1, 3))
    pose_feature = (R[1:] - np.eye(3)[None]).ravel()
    v_posed = v_shaped + model["posedirs"] @ pose_feature
    parent = model["kintree_table"][0].astype(np.int64)
    G = np.zeros((len(R), 4, 4))
    for i in range(len(R)):
        local = np.eye(4)
        local[:3, :3] = R[i]
        local[:3, 3] = J[i] - (J[parent[i]] if i > 0 else 0)
        G[i] = local if i == 0 else G[parent[i]] @ local
    G_rel = G.copy()
    G_rel[:, :3, 3] -= np.einsum("kij,kj->ki", G[:, :3, :3], J)
    T = np.einsum("vk,kij->vij", model["weights"], G_rel)
    v = np.einsum("vij,vj->vi", T[:, :3, :3], v_posed) + T[:, :3, 3]
    return v + trans


def wind_arrays(meta, T):
    rot = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
    strength = np.zeros(T)
    winds = meta.get("wind") or []
    if not winds:
        return rot, strength
    base = meta["human"].get("frame_start", 0)
    piv = sorted(winds[0]["pivot_list"], key=lambda p: p["frame_start"])
    for k, p in enumerate(piv):
        a = max(0, int(p["frame_start"] - base))
        b = T if k + 1 == len(piv) else min(T, int(piv[k + 1]["frame_start"] - base))
        q = np.asarray(p["rotation_quaternion"], float)
        n = np.linalg.norm(q)
        rot[a:b] = q / n if n > 0 else [1.0, 0.0, 0.0, 0.0]
        strength[a:b] = p["strength"]
    return rot, strength


def garment_mesh(uv_groups, n_verts, name):
    """faces (F,3), uv (F,3,2), panel (F,) from the UV pickle's groups."""
    faces, uv, panel = [], [], []
    for pid, (gname, grp) in enumerate(uv_groups.items()):
        vmap = {int(k): np.asarray(v, float) for k, v in grp["vertices"].items()}
        for poly in grp["faces"]:
            poly = [int(x) for x in poly]
            for j in range(1, len(poly) - 1):
                tri = (poly[0], poly[j], poly[j + 1])
                for v in tri:
                    if v >= n_verts or v not in vmap:
                        raise SystemExit(f"convert_dlayers.py: uv_{name}.pkl: group '{gname}': vertex {v} "
                                         f"has no UV or is out of range (N={n_verts})")
                faces.append(tri)
                uv.append([vmap[v][:2] for v in tri])
                panel.append(pid)
    return np.array(faces, np.int64), np.array(uv, float), np.array(panel, np.int64)


def _load_pickle(path):
    with open(path, "rb") as fh:
        return pickle.load(fh, encoding="latin1")


def convert_sequence(root, seq, smpl_dir, models, out_path):
    sdir = os.path.join(root, seq)
    with open(os.path.join(sdir, "meta.json")) as fh:
        meta = json.load(fh)
    human = meta["human"]
    s0, s1 = int(human["seq_start"]), int(human["seq_end"])
    T = s1 - s0
    scale = float(human.get("scale", 10.0))
    mp = human["motion_path"]
    cands = [os.path.join(root, mp), os.path.join(os.path.dirname(os.path.normpath(root)), mp)]
    mpath = next((c for c in cands if os.path.exists(c)), None)
    if mpath is None:
        raise SystemExit(f"convert_dlayers.py: {sdir}/meta.json: human.motion_path '{mp}' not found (tried {cands})")
    motion = _load_pickle(mpath)
    poses = np.asarray(motion["poses"], float).reshape(-1, 72)
    trans = np.asarray(motion["trans"], float).reshape(-1, 3)
    gender = human.get("gender", "female")
    if gender not in models:
        base = os.path.join(smpl_dir, "model_f" if gender == "female" else "model_m")
        path = next((base + e for e in (".npz", ".pkl") if os.path.exists(base + e)), None)
        if path is None:
            raise SystemExit(f"convert_dlayers.py: SMPL model {base}.pkl/.npz not found (pass --smpl-dir)")
        models[gender] = load_smpl(path)
    model = models[gender]
    betas = np.asarray(human.get("betas", np.zeros(10)), float)
    body = np.zeros((T, len(model["v_template"]), 3))
    tr = np.zeros((T, 3))
    for f in range(T):
        m = min(f + s0, len(poses) - 1) if len(poses) > 1 else 0
        body[f] = scale * smpl_vertices(model, poses[m], betas, trans[min(f + s0, len(trans) - 1)])
        tr[f] = scale * trans[min(f + s0, len(trans) - 1)]
    garments = []
    for g in meta["garment"]:
        name = g["name"]
        pk = _load_pickle(os.path.join(sdir, f"{name}.pkl"))
        V = np.asarray(pk["vertices"], float)[:T]
        faces, uv, panel = garment_mesh(_load_pickle(os.path.join(sdir, f"uv_{name}.pkl")), V.shape[1], name)
        cloth = g["cloth"]
        garments.append({"name": name, "type": name, "vertices": V, "faces": faces, "uv": uv, "panel": panel,
                         "rest": np.asarray(pk["tpose"], float),
                         "attrs": {k: float(cloth[k]) for k in ("tension_stiffness", "bending_stiffness", "mass",
                                                                "self_friction")}})
    rot, strength = wind_arrays(meta, T)
    wmax = float(strength.max()) if T else 0.0
    write_sequence(out_path, {
        "fps": 30.0, "gravity": (0.0, 0.0, -9.8), "scale": scale,
        "body": {"vertices": body, "faces": np.asarray(model["f"], np.int64), "translation": tr,
                 "friction": float(human["collision"]["friction"])},
        "garments": garments, "wind": {"rotation": rot, "strength": strength},
        "extra_attrs": {"generator": "generate/convert_dlayers.py (published D-LAYERS release)",
                        "source_sequence": seq, "max_wind_strength": wmax,
                        "tag_wind": "windy" if wmax > 250 else ("calm" if wmax <= 50 else "moderate")}})


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", required=True)
    p.add_argument("--smpl-dir", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--sequences", default="", help="comma-separated ids (default: every id in the splits)")
    a = p.parse_args()
    with open(os.path.join(a.root, "train_val_test.json")) as fh:
        splits_in = json.load(fh)
    splits = {"train": [], "val": [], "test": []}
    for k, ids in splits_in.items():
        splits["val" if k in ("val", "valid") else k].extend(str(i).zfill(5) for i in ids)
    wanted = set(a.sequences.split(",")) if a.sequences else None
    os.makedirs(a.out, exist_ok=True)
    models = {}
    done = {k: [] for k in splits}
    for split, ids in splits.items():
        for seq in ids:
            if wanted is not None and seq not in wanted:
                continue
            convert_sequence(a.root, seq, a.smpl_dir, models, os.path.join(a.out, seq + ".h5"))
            done[split].append(seq)
            print(f"converted {seq} ({split})", flush=True)
    manifest = {"format": "dlayers-h5", "version": 1, "splits": done,
                "source": f"generate/convert_dlayers.py from {os.path.abspath(a.root)}"}
    with open(os.path.join(a.out, "dataset.json"), "w") as fh:
        json.dump(manifest, fh, indent=1)


if __name__ == "__main__":
    main()
