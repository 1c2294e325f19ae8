#!/usr/bin/python3
"""The medium recipe's motion blocks: no two splits share a BVH frame, no block shares one
with the default recipe's training blocks, every block fits a whole sequence at the slowest
speed, and every clip on the machine is used. The time map plays a constant speed exactly
as the linear formula and a warp with mean 1 spans the same frames. The medium_plus recipe
keeps the medium set's sequences and splits and adds training sequences."""
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "../../generate"))
import motion_blocks  # noqa: E402
import numpy as np  # noqa: E402

RECIPES = os.path.join(HERE, "../../generate/recipes")
RULE = {"clips": ["01_01.bvh", "01_03.bvh"], "block_bvh_frames": 480, "split_pattern": "ttvttte"}


def rate(clip):
    with open(os.path.join(motion_blocks.BVH_DIR, clip)) as f:
        for line in f:
            if line.startswith("Frame Time:"):
                return round(1.0 / float(line.split()[2]), 2)


def main():
    default = json.load(open(os.path.join(RECIPES, "default.json")))["scene"]
    medium = json.load(open(os.path.join(RECIPES, "medium.json")))["scene"]
    need = (default["frames"] - default["rest_frames"]) * 4 * 1.25 + 2
    default_train = [b for b in motion_blocks.rule_blocks(RULE, need) if b[0] == "train"]
    assert len(default_train) == 10, default_train
    blocks = motion_blocks.listed_blocks(medium)
    assert not motion_blocks.overlaps(default_train, blocks), motion_blocks.overlaps(default_train, blocks)
    for a in blocks:
        for b in blocks:
            if a is not b:
                assert not motion_blocks.overlaps([a], [b]), (a, b)
    moving = medium["frames"] - medium["rest_frames"]
    for split, clip, lo, hi in blocks:
        n = motion_blocks.bvh_frame_count(clip)
        assert 1 <= lo < hi <= n, (clip, lo, hi, n)
        assert hi - lo - 2 >= moving * rate(clip) / 30.0 * 0.8, (split, clip, lo, hi)
    clips = sorted(f for f in os.listdir(motion_blocks.BVH_DIR) if f.endswith(".bvh"))
    assert sorted({b[1] for b in blocks}) == clips, clips
    assert medium["frames"] - medium["rest_frames"] - medium["ramp_frames"] >= 80
    # medium_plus grows only the training split: medium's seed, scene and val/test indices, so
    # its first 48 sequences are medium's files.
    plus = json.load(open(os.path.join(RECIPES, "medium_plus.json")))
    medium_recipe = json.load(open(os.path.join(RECIPES, "medium.json")))
    assert plus["scene"] == medium and plus["seed"] == medium_recipe["seed"]
    n = medium_recipe["count"]
    n_test = round(n * medium_recipe["test_fraction"])
    n_val = round(n * medium_recipe["val_fraction"])
    assert plus["split_ranges"] == {"val": [[n - n_test - n_val, n - n_test]], "test": [[n - n_test, n]]}, plus
    assert plus["count"] > n
    # Time map: one step is the linear map, bit for bit; a warp with mean factor 1 over the
    # moving frames ends where the constant speed ends, and is increasing.
    keys = np.arange(0.0, 3000.0, 1.0)
    step = 120.0 / 30.0 * 1.13
    assert np.array_equal(motion_blocks.scene_frames_of(keys, 961.5, 9, [step], 20), (keys - 961.5) / step + 9)
    u = np.array([0.8, 1.2, 1.1, 0.9, 1.25])
    u = u * moving / (u * np.minimum(20, moving - 20 * np.arange(5))).sum()
    warped = motion_blocks.scene_frames_of(keys, 961.5, 9, list(step * u), 20)
    assert np.all(np.diff(warped) > 0)
    end = motion_blocks.scene_frames_of(np.array([961.5 + step * moving]), 961.5, 9, list(step * u), 20)
    assert abs(end[0] - (9 + moving)) < 1e-9, end
    print(f"medium: {len(blocks)} blocks over {clips}; disjoint from each other and from the "
          f"{len(default_train)} default training blocks")


def check_large():
    """The large recipe: no two splits share a BVH frame, together they use every frame of
    every clip (frame 0 is a calibration pose), each block fits a sequence at the slowest speed;
    held-out garment kinds exist and leave training kinds."""
    recipe = json.load(open(os.path.join(RECIPES, "large.json")))
    scene = recipe["scene"]
    blocks = motion_blocks.listed_blocks(scene)
    for a in blocks:
        for b in blocks:
            if a is not b:
                assert not motion_blocks.overlaps([a], [b]), (a, b)
    moving = scene["frames"] - scene["rest_frames"]
    for split, clip, lo, hi in blocks:
        assert hi - lo - 2 >= moving * rate(clip) / 30.0 * 0.8, (split, clip, lo, hi)
    clips = sorted(f for f in os.listdir(motion_blocks.BVH_DIR) if f.endswith(".bvh"))
    for clip in clips:
        covered = sorted((lo, hi) for _, c, lo, hi in blocks if c == clip)
        assert covered[0][0] == 1 and covered[-1][1] == motion_blocks.bvh_frame_count(clip), (clip, covered)
        assert all(a[1] == b[0] for a, b in zip(covered, covered[1:])), (clip, covered)
    held = set(scene["heldout_kinds"])
    assert held and held <= set(scene["inner_kinds"]) | set(scene["outer_kinds"])
    assert set(scene["inner_kinds"]) - held and set(scene["outer_kinds"]) - held
    ranges = recipe["split_ranges"]
    n_val = sum(b - a for a, b in ranges["val"])
    n_test = sum(b - a for a, b in ranges["test"])
    assert recipe["count"] - n_val - n_test >= 720 and n_val >= 24 and n_test >= 48, recipe["count"]
    print(f"large: {len(blocks)} blocks cover every frame of {clips}; splits disjoint")


if __name__ == "__main__":
    main()
    check_large()
