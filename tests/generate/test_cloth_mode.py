#!/usr/bin/python3
"""The scene key `cloth` of generate/make_sequence.py and the skinned recipe.

Without arguments (no Blender; bpy and mathutils are stubbed so the module imports): `cloth`
defaults to "blender", an unknown value is refused naming the key, and the skinned recipe is
all train with the large recipe's training motion and no held-out outfit kind drawn.

With --blender (needs Blender, 15-25 s at -t 1): a 12-frame "surface" sequence keeps every
garment edge within 20 % of its rest length in the rest frames, its body equals the "blender"
body of the same seed (solved with 5 steps per frame), and only it carries cloth_source =
surface_deform.
"""
import json
import os
import subprocess
import sys
import tempfile
import types

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
GENERATE = os.path.join(HERE, "../../generate")
RECIPES = os.path.join(GENERATE, "recipes")


def import_make_sequence():
    # Stubs stand in for Blender's modules: only their names are used at import time.
    for name in ("bpy", "mathutils", "mathutils.kdtree", "mathutils.bvhtree"):
        sys.modules.setdefault(name, types.ModuleType(name))
    m = sys.modules["mathutils"]
    for attr in ("Vector", "Quaternion", "Matrix"):
        setattr(m, attr, getattr(m, attr, object))
    sys.modules["mathutils.kdtree"].KDTree = getattr(sys.modules["mathutils.kdtree"], "KDTree", object)
    sys.modules["mathutils.bvhtree"].BVHTree = getattr(sys.modules["mathutils.bvhtree"], "BVHTree", object)
    sys.path.insert(0, GENERATE)
    import make_sequence
    return make_sequence


def parse(ms, scene):
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(scene, f)
    argv = sys.argv
    sys.argv = ["blender", "--", "--out", "x.h5", "--report", "x.json", "--seed", "1", "--config", f.name]
    try:
        return ms.parse_args()[1]
    finally:
        sys.argv = argv
        os.unlink(f.name)


def check_key(ms):
    assert ms.DEFAULTS["cloth"] == "blender", ms.DEFAULTS["cloth"]
    assert parse(ms, {})["cloth"] == "blender"
    assert parse(ms, {"cloth": "surface"})["cloth"] == "surface"
    try:
        parse(ms, {"cloth": "skinned"})
    except SystemExit as e:
        msg = str(e)
        assert "'cloth'" in msg and "skinned" in msg and "surface" in msg, msg
    else:
        raise AssertionError("an unknown cloth value must be refused")


def check_recipe(ms):
    skinned = json.load(open(os.path.join(RECIPES, "skinned.json")))
    large = json.load(open(os.path.join(RECIPES, "large.json")))
    scene = skinned["scene"]
    assert scene["cloth"] == "surface"
    assert skinned["seed"] != large["seed"]
    assert skinned["count"] == 160 and scene["frames"] == 100
    # The driver makes every index train when split_ranges lists no split.
    assert skinned["split_ranges"] == {} and "val_fraction" not in skinned and "test_fraction" not in skinned
    assert set(scene["motion_blocks"]) == {"train"}
    assert scene["motion_blocks"]["train"] == large["scene"]["motion_blocks"]["train"]
    for k, v in large["scene"].items():
        if k not in ("motion_blocks", "cloth"):
            assert scene[k] == v, k
    cfg = parse(ms, scene)   # every key known
    held = set(cfg["heldout_kinds"])
    for seed in range(300):
        pair = ms.sample_outfit_kinds(np.random.default_rng(seed), cfg, "train")
        assert not held & set(pair), (seed, pair)


def run_blender(tmp, scene, name, seed):
    cfg = os.path.join(tmp, name + ".json")
    with open(cfg, "w") as f:
        json.dump(scene, f)
    out = os.path.join(tmp, name + ".h5")
    cmd = ["blender", "-b", "--factory-startup", "-t", "1", "--python", os.path.join(GENERATE, "make_sequence.py"),
           "--", "--out", out, "--report", os.path.join(tmp, name + ".report.json"), "--seed", str(seed),
           "--split", "train", "--config", cfg]
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert r.returncode == 0 and os.path.exists(out), r.stdout[-3000:]
    return out


def check_blender():
    import h5py
    scene = dict(json.load(open(os.path.join(RECIPES, "skinned.json")))["scene"], frames=12)
    with tempfile.TemporaryDirectory(prefix="layersnet_test_cloth_") as tmp:
        surface = run_blender(tmp, scene, "surface", 5)
        # Fewer solver steps keep the twin cheap; no draw depends on them.
        blender = run_blender(tmp, dict(scene, cloth="blender", cloth_quality=5), "blender", 5)
        with h5py.File(surface) as s, h5py.File(blender) as b:
            assert s.attrs["cloth_source"] == "surface_deform"
            assert "Surface Deform" in s.attrs["generator"]
            assert "cloth_source" not in b.attrs
            assert np.array_equal(s["body/vertices"][:], b["body/vertices"][:]), "bodies of the same seed differ"
            rest_frames = int(s.attrs["rest_frames"])
            for name in s["garments"]:
                g = s["garments"][name]
                v, faces, rest = g["vertices"][:rest_frames], g["faces"][:], g["rest"][:]
                pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
                e = np.unique(np.sort(pairs, 1), axis=0)
                l0 = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
                stretch = np.abs(np.linalg.norm(v[:, e[:, 0]] - v[:, e[:, 1]], axis=2) / l0 - 1)
                assert stretch.max() <= 0.2, (name, float(stretch.max()))


if __name__ == "__main__":
    ms = import_make_sequence()
    if "--blender" in sys.argv[1:]:
        check_blender()
    else:
        check_key(ms)
        check_recipe(ms)
    print("test_cloth_mode: ok")
