"""Motion blocks: the stretches of BVH frames each data split may draw its motion from,
and the time map that plays a clip on the scene's timeline (numpy, no Blender).

Two ways to give them in a scene config: the rule (`clips`, `block_bvh_frames`,
`split_pattern`: every clip cut into equal blocks, block k over all clips goes to split
split_pattern[k % len]), or an explicit `motion_blocks` list per split. Splits must never
share motion, and a recipe may also have to avoid another recipe's training motion:
`overlaps` finds shared frames.
"""
import math
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


# Procedural overlays on the mocap (scene key "procedural"); every key may be overridden.
PROCEDURAL_DEFAULTS = {
    "probability": 0.6,              # share of sequences that get overlays (the rest: mocap as is)
    "max_turns_per_s": 1.5,          # yaw rate bound of spins and turns
    "turn_segment_frames": [6, 30],  # piecewise-constant yaw rate: abrupt starts and stops
    "still_probability": 0.35,       # a segment without turning
    "hop_probability": 0.4,
    "hops": [1, 3],
    "hop_height_m": [0.05, 0.2],
    "arm_swing_probability": 0.5,
    "arm_swing_deg": [15.0, 40.0],   # forward-back swing of the upper arms (shoulder flexion/extension)
    "arm_swing_hz": [0.6, 1.6],
}
GRAVITY = 9.8


def sample_procedural(rng, cfg, frames, start_frame):
    """Draws the overlays of one sequence (pure numpy: tested without Blender). Returns a dict:
    active; yaw_deg (frames,) cumulative yaw per stored frame; lift (frames,) metres of hop
    height; arm_swing {deg, hz, phase, opposite} or None. Overlays begin at scene frame
    `start_frame` (after the ramp), so garments settle on the rest pose as before."""
    p = dict(PROCEDURAL_DEFAULTS)
    unknown = set(cfg) - set(PROCEDURAL_DEFAULTS)
    if unknown:
        raise SystemExit(f"make_sequence.py: procedural: unknown keys {sorted(unknown)}; known: {sorted(PROCEDURAL_DEFAULTS)}")
    p.update(cfg)
    yaw = np.zeros(frames)
    lift = np.zeros(frames)
    out = {"active": bool(rng.random() < p["probability"]), "yaw_deg": yaw.tolist(), "lift_m": lift.tolist(),
           "arm_swing": None, "turn_rates": []}
    if not out["active"]:
        return out
    first = start_frame - 1                      # stored index of the first overlaid frame
    rate = np.zeros(frames)                      # degrees per frame
    f = first
    while f < frames:
        n = int(rng.integers(p["turn_segment_frames"][0], p["turn_segment_frames"][1] + 1))
        r = 0.0 if rng.random() < p["still_probability"] else \
            float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0) * p["max_turns_per_s"] * 360.0 / 30.0)
        rate[f:f + n] = r
        out["turn_rates"].append([f, min(frames, f + n), r * 30.0 / 360.0])
        f += n
    yaw[1:] = np.cumsum(rate[:-1])
    if rng.random() < p["hop_probability"]:
        for _ in range(int(rng.integers(p["hops"][0], p["hops"][1] + 1))):
            h = float(rng.uniform(*p["hop_height_m"]))
            air = 2.0 * math.sqrt(2.0 * h / GRAVITY) * 30.0       # frames in the air
            t0 = float(rng.uniform(first, max(first, frames - air - 1)))
            t = np.arange(frames) - t0
            inside = (t > 0) & (t < air)
            tt = t[inside] / 30.0
            lift[inside] = np.maximum(lift[inside], math.sqrt(2 * GRAVITY * h) * tt - 0.5 * GRAVITY * tt * tt)
    if rng.random() < p["arm_swing_probability"]:
        out["arm_swing"] = {"deg": float(rng.uniform(*p["arm_swing_deg"])), "hz": float(rng.uniform(*p["arm_swing_hz"])),
                            "phase": float(rng.uniform(0, 2 * math.pi)), "opposite": bool(rng.random() < 0.7),
                            "start_frame": int(start_frame)}
    out["yaw_deg"], out["lift_m"] = yaw.tolist(), lift.tolist()
    return out
