#!/usr/bin/python3
"""Held-out garment kinds (no Blender; make_sequence imports with Blender's modules stubbed).

By default only test draws held-out kinds, and val and train draw exactly as before the key
heldout_splits existed (no extra random number), so the large set's files stay reproducible.
The large_unseen_val recipe is the large recipe's scene on its val motion blocks with every val
outfit holding a held-out kind, and heldout_splits refuses train. The large_overskirt recipe is
its scene on its training blocks whose every outfit is a seen inner kind under a long overskirt,
never a held-out kind."""
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from test_cloth_mode import RECIPES, import_make_sequence, parse  # noqa: E402


def draws(ms, cfg, split, n=300):
    return [ms.sample_outfit_kinds(np.random.default_rng(seed), cfg, split) for seed in range(n)]


def main():
    ms = import_make_sequence()
    large = json.load(open(os.path.join(RECIPES, "large.json")))
    unseen = json.load(open(os.path.join(RECIPES, "large_unseen_val.json")))
    cfg = parse(ms, large["scene"])
    held = set(cfg["heldout_kinds"])
    assert cfg["heldout_splits"] == ["test"], cfg["heldout_splits"]
    test = draws(ms, cfg, "test")
    assert any(held & set(p) for p in test) and any(not held & set(p) for p in test)
    for split in ("train", "val"):
        assert not any(held & set(p) for p in draws(ms, cfg, split)), split
    # A val draw leaves the generator where a draw of the seen kinds alone leaves it.
    rng = np.random.default_rng(11)
    ms.sample_outfit_kinds(rng, cfg, "val")
    ref = np.random.default_rng(11)
    ref.choice([k for k in cfg["inner_kinds"] if k not in held])
    ref.choice([k for k in cfg["outer_kinds"] if k not in held])
    assert rng.random() == ref.random()

    scene = unseen["scene"]
    assert unseen["seed"] not in (large["seed"], 4)  # draws of its own, not the large or sleeves recipe's
    assert set(unseen["split_ranges"]) == {"val"} and unseen["split_ranges"]["val"] == [[0, unseen["count"]]]
    assert scene["motion_blocks"] == {"val": large["scene"]["motion_blocks"]["val"]}
    for k, v in large["scene"].items():
        if k not in ("motion_blocks", "heldout_probability"):
            assert scene[k] == v, k
    ucfg = parse(ms, scene)
    assert all(held & set(p) for p in draws(ms, ucfg, "val"))
    assert not any(held & set(p) for p in draws(ms, ucfg, "train"))
    try:
        ms.sample_outfit_kinds(np.random.default_rng(0), dict(ucfg, heldout_splits=["train", "val"]), "val")
    except SystemExit as e:
        assert "heldout_splits" in str(e) and "train" in str(e), str(e)
    else:
        raise AssertionError("heldout_splits with train must be refused")
    over = json.load(open(os.path.join(RECIPES, "large_overskirt.json")))
    assert over["seed"] not in (large["seed"], unseen["seed"], 4) and over["split_ranges"] == {}
    assert over["scene"]["motion_blocks"] == {"train": large["scene"]["motion_blocks"]["train"]}
    for k, v in large["scene"].items():
        if k not in ("motion_blocks", "outer_kinds"):
            assert over["scene"][k] == v, k
    assert over["gates"] == large["gates"]
    ocfg = parse(ms, over["scene"])
    pairs = draws(ms, ocfg, "train")
    assert all(o == "overskirt_long" and i not in held for i, o in pairs), pairs[:5]
    assert len({i for i, _ in pairs}) == len([k for k in ocfg["inner_kinds"] if k not in held])
    print("test_heldout_outfits: ok")


if __name__ == "__main__":
    main()
