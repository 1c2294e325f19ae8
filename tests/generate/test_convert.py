#!/usr/bin/python3
"""Builds a small mock of the D-LAYERS release layout (meta.json, garment and UV pickles,
SMPL motion, a stand-in SMPL model: a cube with 24 joints) and checks the converter:
the files pass the D-LAYERS-H5 checker and hold the expected body, wind, UV and panels."""
import json
import os
import pickle
import subprocess
import sys
import tempfile

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
CONVERTER = os.path.join(HERE, "../../generate/convert_dlayers.py")
CHECKER = os.path.join(HERE, "../../dataset/check_dlayers_h5.py")
T = 4


def cube_model(path):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (0, 2)], float) * 0.1
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    # Orient faces outwards (the cube's centre is (0, 0, 0.1)).
    c = v[f].mean(1) - [0, 0, 0.1]
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    f[(n * c).sum(1) < 0] = f[(n * c).sum(1) < 0][:, [0, 2, 1]]
    weights = np.zeros((8, 24))
    weights[:, 0] = 1.0
    kin = np.stack([np.r_[-1, np.arange(23)], np.arange(24)])
    np.savez(path, v_template=v, shapedirs=np.zeros((8, 3, 10)), posedirs=np.zeros((8, 3, 207)),
             J_regressor=np.full((24, 8), 1 / 8), weights=weights, kintree_table=kin, f=f)
    return v, f


def garment(seq_dir, name, radius, rng):
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = lambda z: np.stack([radius * np.sin(ang), -radius * np.cos(ang), np.full(8, z)], 1)
    rest = np.concatenate([ring(1.5), ring(0.5)])
    faces = [[i, 8 + i, 8 + (i + 1) % 8] for i in range(8)] + [[i, 8 + (i + 1) % 8, (i + 1) % 8] for i in range(8)]
    V = rest[None] + 0.01 * rng.normal(size=(T, 16, 3))
    with open(os.path.join(seq_dir, f"{name}.pkl"), "wb") as fh:
        pickle.dump({"vertices": V, "faces": np.array(faces), "tpose": rest}, fh)
    groups = {}
    for p, idx in enumerate([range(0, 8), range(8, 16)]):
        fl = [faces[i] for i in idx]
        vs = sorted({v for fc in fl for v in fc})
        groups[f"panel{p}"] = {"vertices": {v: np.array([0.1 * v, 0.2 * p]) for v in vs}, "faces": fl}
    with open(os.path.join(seq_dir, f"uv_{name}.pkl"), "wb") as fh:
        pickle.dump(groups, fh)
    return V


def main():
    rng = np.random.default_rng(0)
    tmp = tempfile.mkdtemp(prefix="layersnet_convert_")
    root, smpl, out = (os.path.join(tmp, d) for d in ("data", "smpl", "out"))
    os.makedirs(os.path.join(root, "motion"))
    os.makedirs(smpl)
    v_template, _ = cube_model(os.path.join(smpl, "model_f.npz"))
    ids = {"train": ["00001"], "val": ["00002"], "test": ["00003"]}
    with open(os.path.join(root, "train_val_test.json"), "w") as fh:
        json.dump(ids, fh)
    inner = {}
    for split, (seq,) in ids.items():
        sdir = os.path.join(root, seq)
        os.makedirs(sdir)
        trans = rng.normal(size=(T + 2, 3)) * 0.1
        with open(os.path.join(root, "motion", seq + ".pkl"), "wb") as fh:
            pickle.dump({"poses": np.zeros((T + 2, 72)), "trans": trans}, fh)
        meta = {"human": {"gender": "female", "betas": [0.0] * 10, "motion_path": f"motion/{seq}.pkl",
                          "seq_start": 1, "seq_end": 1 + T, "frame_start": 10, "scale": 10,
                          "collision": {"friction": 55.0}},
                "garment": [{"name": "tee", "cloth": {"tension_stiffness": 20, "bending_stiffness": 30,
                                                      "mass": 0.3, "self_friction": 50}},
                            {"name": "jacket", "cloth": {"tension_stiffness": 60, "bending_stiffness": 90,
                                                         "mass": 0.5, "self_friction": 70}}],
                "wind": [{"pivot_list": [{"frame_start": 12, "rotation_quaternion": [0, 0, 1, 0], "strength": 300}]}]}
        with open(os.path.join(sdir, "meta.json"), "w") as fh:
            json.dump(meta, fh)
        inner[seq] = (garment(sdir, "tee", 1.0, rng), trans)
        garment(sdir, "jacket", 1.5, rng)
    subprocess.run([sys.executable, CONVERTER, "--root", root, "--smpl-dir", smpl, "--out", out], check=True)
    subprocess.run([sys.executable, CHECKER, out], check=True)
    with open(os.path.join(out, "dataset.json")) as fh:
        assert json.load(fh)["splits"] == ids
    with h5py.File(os.path.join(out, "00002.h5"), "r") as f:
        V, trans = inner["00002"]
        assert list(f["garments"].attrs["order"]) == ["tee", "jacket"]
        np.testing.assert_allclose(f["garments/tee/vertices"][:], V, rtol=1e-6, atol=1e-6)
        # Zero pose: body = scale * (template + trans of motion frame f + seq_start).
        np.testing.assert_allclose(f["body/vertices"][1], 10 * (v_template + trans[2]), atol=1e-5)
        np.testing.assert_allclose(f["wind/strength"][:], [0, 0, 300, 300])
        np.testing.assert_allclose(f["wind/rotation"][0], [1, 0, 0, 0])
        np.testing.assert_allclose(f["wind/rotation"][3], [0, 0, 1, 0])
        assert sorted(set(f["garments/jacket/panel"][:])) == [0, 1]
        assert f["garments/jacket"].attrs["tension_stiffness"] == 60
        assert f["body"].attrs["friction"] == 55
        assert f.attrs["scale"] == 10
    print("ok: converted 3 mock sequences")


main()
