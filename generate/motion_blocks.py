"""Motion blocks: the stretches of BVH frames each data split may draw its motion from,
and the time map that plays a clip on the scene's timeline (numpy, no Blender).

Two ways to give them in a scene config: the rule (`clips`, `block_bvh_frames`,
`split_pattern`: every clip cut into equal blocks, block k over all clips goes to split
split_pattern[k % len]), or an explicit `motion_blocks` list per split. Splits must never
share motion, and a recipe may also have to avoid another recipe's training motion:
`overlaps` finds shared frames.
"""
import os

import numpy as np

BVH_DIR = "/usr/share/assimp/models/BVH"
SPLIT_CODE = {"train": "t", "val": "v", "test": "e"}


def bvh_frame_count(clip, bvh_dir=BVH_DIR):
    with open(os.path.join(bvh_dir, clip)) as f:
        for line in f:
            if line.startswith("Frames:"):
                return int(line.split()[1])
    raise RuntimeError(f"{clip}: no 'Frames:' line")


def rule_blocks(cfg, min_frames, bvh_dir=BVH_DIR):
    """[(split, clip, first, end)] of the rule; a block holds at least `min_frames`
    BVH frames. Frame 0 of a clip is a calibration pose and never used."""
    out, k = [], 0
    inverse = {code: split for split, code in SPLIT_CODE.items()}
    for clip in cfg["clips"]:
        n = bvh_frame_count(clip, bvh_dir)
        size = max(cfg["block_bvh_frames"], int(min_frames) + 10)
        for start in range(1, n - size + 1, size):
            out.append((inverse[cfg["split_pattern"][k % len(cfg["split_pattern"])]], clip, start, start + size))
            k += 1
    return out


def listed_blocks(cfg):
    """[(split, clip, first, end)] of an explicit `motion_blocks` config."""
    return [(split, clip, int(lo), int(hi)) for split, blocks in cfg["motion_blocks"].items()
            for clip, lo, hi in blocks]


def blocks_of(cfg, min_frames, bvh_dir=BVH_DIR):
    return listed_blocks(cfg) if cfg.get("motion_blocks") else rule_blocks(cfg, min_frames, bvh_dir)


def overlaps(a, b):
    """Pairs of blocks from lists a and b that share a BVH frame of the same clip."""
    return [(x, y) for x in a for y in b if x[1] == y[1] and x[2] < y[3] and y[2] < x[3]]


def scene_frames_of(bvh_frames, bvh_start, scene_start, steps, segment_frames):
    """Time map BVH frame -> scene frame: from scene frame `scene_start` (showing BVH frame
    `bvh_start`) on, segment k of `segment_frames` scene frames advances `steps[k]` BVH frames
    per scene frame (one step: constant speed; several: a time warp). Frames outside the
    segments continue the first or last one."""
    steps = np.asarray(steps, float)
    bvh_knots = bvh_start + np.concatenate([[0.0], np.cumsum(steps * segment_frames)])[:-1]
    k = np.clip(np.searchsorted(bvh_knots, bvh_frames, side="right") - 1, 0, len(steps) - 1)
    return (bvh_frames - bvh_knots[k]) / steps[k] + (scene_start + k * segment_frames)
