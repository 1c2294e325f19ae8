"""Simulates one D-LAYERS-like sequence with Blender's cloth solver and writes it as
D-LAYERS-H5 (plus a JSON sidecar with tags, quality gates and timings).

Run inside Blender:
  blender -b --factory-startup -t 2 --python generate/make_sequence.py -- \
      --out SEQ.h5 --report SEQ.json --seed 7 --split train [--config recipe.json]

Everything random is drawn from numpy's generator seeded with --seed; the wind field has
a fixed noise seed, so the same seed gives the same file on the same machine.
Scene: the MakeHuman body driven by a CMU clip, two garment layers merged into one
cloth object with self-collision, piecewise-constant wind, the world scaled x10 before
simulation, gravity (0, 0, -9.8) scene units/s^2, z up, 30 fps.
Scene key "cloth": "surface" skips the solver: the outfit is carried on the body (Surface
Deform), for physics-only pretraining; such files are not ground truth.
"""
import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bpy  # noqa: E402
import mathutils  # noqa: E402
from mathutils.kdtree import KDTree  # noqa: E402
import numpy as np  # noqa: E402

import body_rig  # noqa: E402
import motion_blocks  # noqa: E402
import outfits  # noqa: E402
import quality  # noqa: E402
import wind_field  # noqa: E402
from garments import SCENE_SCALE, BodyProfile  # noqa: E402
from write_h5 import write_sequence  # noqa: E402

DEFAULTS = {
    "frames": 48,                 # stored frames, 30 fps
    "rest_frames": 8,             # body in the rest pose while garments settle
    "ramp_frames": 15,            # rest pose -> mocap blend
    "leg_spread_deg": 7.0,        # thighs turned apart in the rest pose (room for trousers)
    "decimate_ratio": 0.3,        # 13,380 -> ~4k body vertices
    "cloth_quality": 30,          # solver steps per frame (25 was unstable at x10)
    "clips": ["01_01.bvh", "01_03.bvh"],
    "block_bvh_frames": 480,      # motion blocks (4 s at 120 Hz) assigned to splits
    "split_pattern": "ttvttte",   # block k (over all clips) -> split: t train, v val, e test
    # Explicit blocks instead of the three keys above: {"train": [[clip, first BVH frame,
    # end BVH frame], ...], "val": [...], "test": [...]}; a clip is drawn first, then a block.
    "motion_blocks": None,
    "speed_range": [0.8, 1.25],   # mean playback speed (capped so the span fits the block)
    "time_warp": 0.0,             # segment speeds vary by up to +-this fraction around the mean
    "time_warp_segment_frames": 20,
    "pose_blend_range": [1.0, 1.0],  # rotation influence of the mocap after the ramp (< 1: blended with the rest pose)
    "yaw_range_deg": [-180.0, 180.0],
    "mirror_probability": 0.5,
    "arm_abduction_deg": [22.0, 28.0],
    "inner_kinds": list(outfits.INNER_KINDS),
    "outer_kinds": list(outfits.OUTER_KINDS),
    "ranges": {"tension_stiffness": [15, 100], "bending_stiffness": [15, 200], "mass": [0.2, 0.8],
               "self_friction": [40, 80], "body_friction": [40, 80]},
    "wind_calm_probability": 0.35,    # every segment <= 50
    "wind_windy_probability": 0.45,   # one segment in (250, 400], others 0..400
    "wind_segments": [1, 3],
    "field_seed": 1,
    "distance_body": 0.1,         # cloth-body collision distance, scene units (1 cm)
    "distance_self": 0.06,        # cloth-cloth, scene units
    "garment_spacing_m": outfits.SPACING,  # rest edge length of the garments (metres)
    "ring_vertices": outfits.COLS,         # vertices around a ring (multiple of 8)
    # Std (scene units) of Gaussian noise on the cloth's starting vertices, drawn from its own
    # generator so every other draw is unchanged: a twin of a sequence that differs only by
    # an imperceptible nudge measures how predictable the solver's cloth is.
    "cloth_jitter": 0.0,
    # Factor on every drawn wind strength, applied after the draws so nothing else changes: a
    # twin with 0 measures how much of a sequence's cloth motion the wind makes.
    "wind_scale": 1.0,
    # Opt-in keys of the large recipe (their defaults reproduce the older recipes bit for bit).
    # "sphere": direction uniform on the sphere; "horizontal": any yaw, elevation uniform within
    # +-wind_elevation_deg of the ground plane.
    "wind_direction": "sphere",
    "wind_elevation_deg": 30.0,
    # Blender's field strength = stored strength x this factor (the files keep the stored,
    # D-LAYERS-range value and the factor as attribute wind_field_factor); README "The wind".
    "wind_field_factor": 1.0,
    # How the two layers' stiffness reaches Blender's one cloth object. "outer_max": base = inner,
    # maximum = outer, group weight 1 on the outer layer; Blender uses base + w*|max - base|, so
    # an outer value below the inner one is simulated as 2*inner - outer (the older recipes).
    # "per_layer": base = the smaller value, weight 1 on the layer with the larger one, per
    # property: each layer is simulated with the value its file stores.
    "stiffness_groups": "outer_max",
    # Procedural overlays on the mocap (spins and turns, hops, arm swings); None: off. Keys:
    # motion_blocks.PROCEDURAL_DEFAULTS.
    "procedural": None,
    # Garment kinds training never sees (unseen outfits): a sequence of a split listed in
    # heldout_splits draws an outfit with one of them with probability heldout_probability;
    # train never does. Listing val lets validation choose settings for unseen outfits.
    "heldout_kinds": [],
    "heldout_probability": 0.5,
    "heldout_splits": ["test"],
    # "blender": the cloth solver (ground truth). "surface": no solver; the outfit is carried by
    # the body through a Surface Deform bound in the rest pose (cheap starting states for
    # physics-only pretraining, never supervised targets; file attr cloth_source).
    "cloth": "blender",
}
CLOTH_MODES = ("blender", "surface")
SPLIT_CODE = motion_blocks.SPLIT_CODE


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", required=True)
    p.add_argument("--report", required=True)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--split", default="train", choices=list(SPLIT_CODE))
    p.add_argument("--config", default=None, help="JSON file overriding DEFAULTS keys")
    a = p.parse_args(argv)
    cfg = json.loads(json.dumps(DEFAULTS))
    if a.config:
        with open(a.config) as f:
            over = json.load(f)
        unknown = set(over) - set(DEFAULTS)
        if unknown:
            raise SystemExit(f"make_sequence.py: {a.config}: unknown keys {sorted(unknown)}; "
                             f"known: {sorted(DEFAULTS)}")
        cfg.update(over)
    if cfg["cloth"] not in CLOTH_MODES:
        raise SystemExit(f"make_sequence.py: scene key 'cloth' is {cfg['cloth']!r}; "
                         f"known: {', '.join(CLOTH_MODES)}")
    return a, cfg


def sample_listed_motion(rng, cfg, split):
    """Clip, first BVH frame and mean speed inside one of the split's listed blocks: a clip
    first (so a clip with many blocks does not crowd out the others), then a block, then a
    speed capped so that the whole span stays inside the block."""
    blocks = cfg["motion_blocks"].get(split, [])
    clips = list(dict.fromkeys(b[0] for b in blocks))
    if not clips:
        raise SystemExit(f"make_sequence.py: motion_blocks has no block for split '{split}'")
    clip = clips[int(rng.integers(len(clips)))]
    mine = [b for b in blocks if b[0] == clip]
    _, lo, hi = mine[int(rng.integers(len(mine)))]
    step = body_rig.bvh_rate(clip) / 30.0
    moving = cfg["frames"] - cfg["rest_frames"]
    fastest = min(cfg["speed_range"][1], (hi - lo - 2) / (moving * step))
    if fastest < cfg["speed_range"][0]:
        raise SystemExit(f"make_sequence.py: motion block {clip} [{lo}, {hi}) is too short for "
                         f"{moving} frames at speed {cfg['speed_range'][0]}; lengthen it or drop it")
    speed = float(rng.uniform(cfg["speed_range"][0], fastest))
    span = moving * step * speed
    start = float(rng.uniform(lo, max(lo, hi - span - 1)))
    return clip, start, speed


def sample_time_warp(rng, cfg):
    """Per-segment speed factors with mean 1 over the moving frames (so the span is the
    constant-speed one), or [1] without a warp."""
    if cfg["time_warp"] <= 0:
        return [1.0]
    moving = cfg["frames"] - cfg["rest_frames"]
    seg = cfg["time_warp_segment_frames"]
    lengths = np.minimum(seg, moving - seg * np.arange(-(-moving // seg)))
    u = rng.uniform(1 - cfg["time_warp"], 1 + cfg["time_warp"], size=len(lengths))
    return [float(x) for x in u * moving / (u * lengths).sum()]


def sample_motion(rng, cfg, split):
    """Clip, first BVH frame and speed, inside a motion block that belongs to `split`."""
    if cfg["motion_blocks"]:
        return sample_listed_motion(rng, cfg, split)
    step = body_rig.bvh_rate(cfg["clips"][0]) / 30.0
    need = (cfg["frames"] - cfg["rest_frames"]) * step * cfg["speed_range"][1] + 2
    blocks = [b[1:] for b in motion_blocks.rule_blocks(cfg, need, body_rig.BVH_DIR) if b[0] == split]
    if not blocks:
        raise SystemExit(f"make_sequence.py: no motion block of {need:.0f} BVH frames for split "
                         f"'{split}'; lower 'frames' or 'block_bvh_frames'")
    clip, lo, hi = blocks[int(rng.integers(len(blocks)))]
    speed = float(rng.uniform(*cfg["speed_range"]))
    span = (cfg["frames"] - cfg["rest_frames"]) * step * speed
    start = float(rng.uniform(lo, max(lo, hi - span - 1)))
    return clip, start, speed


def sample_outfit_kinds(rng, cfg, split):
    """(inner, outer) kinds. A split in heldout_splits draws an outfit with at least one held-out
    kind with probability heldout_probability; otherwise, and always for train, only kinds not
    held out."""
    held = set(cfg["heldout_kinds"])
    unknown = held - set(cfg["inner_kinds"]) - set(cfg["outer_kinds"])
    if unknown:
        raise SystemExit(f"make_sequence.py: heldout_kinds {sorted(unknown)} are not in inner_kinds or outer_kinds")
    seen_inner = [k for k in cfg["inner_kinds"] if k not in held]
    seen_outer = [k for k in cfg["outer_kinds"] if k not in held]
    if not seen_inner or not seen_outer:
        raise SystemExit("make_sequence.py: heldout_kinds leave no inner or no outer kind for training")
    bad = set(cfg["heldout_splits"]) - {"val", "test"}
    if bad:
        raise SystemExit(f"make_sequence.py: heldout_splits {sorted(bad)}: list val and/or test (a kind "
                         "train draws is not held out)")
    if split in cfg["heldout_splits"] and rng.random() < cfg["heldout_probability"]:
        pairs = [(i, o) for i in cfg["inner_kinds"] for o in cfg["outer_kinds"] if i in held or o in held]
        i, o = pairs[int(rng.integers(len(pairs)))]
        return str(i), str(o)
    return str(rng.choice(seen_inner)), str(rng.choice(seen_outer))


def sample_wind(rng, cfg, T):
    """Piecewise-constant wind: pivots (frame, quaternion wxyz, strength); no wind before
    the first pivot, as in D-LAYERS."""
    n = int(rng.integers(cfg["wind_segments"][0], cfg["wind_segments"][1] + 1))
    starts = sorted(int(x) for x in rng.integers(0, max(1, T // 3), size=1)) + \
        sorted(int(x) for x in rng.integers(T // 3, T - 1, size=n - 1))
    u = rng.random()
    if u < cfg["wind_calm_probability"]:
        strengths = rng.uniform(0, 50, size=n)
    elif u < cfg["wind_calm_probability"] + cfg["wind_windy_probability"]:
        strengths = rng.uniform(0, 400, size=n)
        strengths[int(rng.integers(n))] = rng.uniform(250, 400)
    else:
        strengths = rng.uniform(0, 400, size=n)
    pivots = []
    for s, st in zip(starts, strengths):
        if cfg["wind_direction"] == "horizontal":
            q = wind_field.horizontal_wind_quaternion(rng, cfg["wind_elevation_deg"])
        elif cfg["wind_direction"] == "sphere":
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            if q[0] < 0:
                q = -q
        else:
            raise SystemExit(f"make_sequence.py: wind_direction '{cfg['wind_direction']}' is neither 'sphere' nor "
                             "'horizontal'")
        pivots.append({"frame": s, "rotation": [float(x) for x in q], "strength": float(st)})
    return pivots


def wind_arrays(pivots, T):
    rot = np.zeros((T, 4))
    rot[:, 0] = 1.0
    strength = np.zeros(T)
    for k, p in enumerate(pivots):
        end = pivots[k + 1]["frame"] if k + 1 < len(pivots) else T
        rot[p["frame"]:end] = p["rotation"]
        strength[p["frame"]:end] = p["strength"]
    return rot, strength


def add_wind(pivots, centre, field_seed, field_factor=1.0):
    """A wind force field keyed with constant interpolation; placed 100 units upwind so
    the whole scene is on its +Z side. Stored frame i is scene frame i + 1."""
    bpy.ops.object.effector_add(type="WIND", location=(0, 0, 0))
    wind = bpy.context.view_layer.objects.active
    wind.rotation_mode = "QUATERNION"
    wind.field.seed = field_seed
    wind.field.noise = 0.0
    wind.field.flow = 0.0
    wind.field.strength = 0.0
    wind.field.keyframe_insert("strength", frame=1)
    for p in pivots:
        q = mathutils.Quaternion(p["rotation"])
        d = q.to_matrix() @ mathutils.Vector((0, 0, 1))
        wind.rotation_quaternion = q
        wind.location = mathutils.Vector(centre) - 100.0 * d
        wind.field.strength = p["strength"] * field_factor if field_factor != 1.0 else p["strength"]
        f = p["frame"] + 1
        wind.keyframe_insert("rotation_quaternion", frame=f)
        wind.keyframe_insert("location", frame=f)
        wind.field.keyframe_insert("strength", frame=f)
    for fc in wind.animation_data.action.fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "CONSTANT"
    return wind


def carry_on_body(obj, body):
    """Surface Deform of `obj` onto the body, bound at frame 1 (the rest pose, where the
    garments were built); the body must already be deformed by its armature."""
    deforming = [m.type for m in body.modifiers if m.type != "COLLISION"]
    if deforming != ["ARMATURE"]:
        raise RuntimeError(f"make_sequence.py: cloth 'surface' needs the body deformed by its Armature modifier "
                           f"alone, found modifiers {[m.type for m in body.modifiers]}")
    bpy.context.scene.frame_set(1)
    mod = obj.modifiers.new("surface", "SURFACE_DEFORM")
    mod.target = body
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.surfacedeform_bind(modifier=mod.name)
    if not mod.is_bound:
        raise RuntimeError("make_sequence.py: cloth 'surface': Surface Deform of the outfit onto the body did not "
                           "bind at frame 1 (Blender's message is in the log above)")
    return mod


def make_cloth(garments, body_w, bone_names, body_rest, layer_attrs, cfg, torso_bones):
    """One mesh object holding every layer (self-collision keeps the layers apart), with
    an Armature modifier (for the pinned edges) before the Cloth modifier; with cfg cloth
    "surface", only a Surface Deform onto the body (no solver)."""
    verts = np.concatenate([g.verts for g in garments])
    if cfg["cloth_jitter"] > 0:
        verts = verts + np.random.default_rng(0).normal(0.0, cfg["cloth_jitter"], verts.shape)
    offs = np.cumsum([0] + [len(g.verts) for g in garments])
    faces = np.concatenate([g.faces + o for g, o in zip(garments, offs)])
    me = bpy.data.meshes.new("outfit")
    me.from_pydata(verts.tolist(), [], faces.tolist())
    me.update()
    obj = bpy.data.objects.new("outfit", me)
    bpy.context.scene.collection.objects.link(obj)
    pin = np.concatenate([g.pin for g in garments])
    outer = np.concatenate([np.full(len(g.verts), float(i == len(garments) - 1)) for i, g in enumerate(garments)])
    # Self-collision only where the layers can meet: the outer layer and the part of the
    # inner one under it (down to 10 cm below the outer hem). Blender's group lists the
    # triangles to EXCLUDE; leg-to-leg contacts of trousers are left to the body collider
    # (they cost most of the solver time otherwise).
    outer_hem = garments[-1].verts[:, 2].min()
    no_self = ((outer == 0) & (verts[:, 2] < outer_hem - 0.1 * SCENE_SCALE)).astype(float)
    stiffness, stiffness_weights = outfits.stiffness_groups(layer_attrs, cfg["stiffness_groups"])
    layer_of_vertex = np.concatenate([np.full(len(g.verts), i) for i, g in enumerate(garments)])
    vertex_groups = [("pin", pin)] + [(name, np.asarray(w)[layer_of_vertex]) for name, w in stiffness_weights]
    for name, w in vertex_groups + [("no_self_collision", no_self)]:
        vg = obj.vertex_groups.new(name=name)
        for i in np.nonzero(w > 0)[0]:
            vg.add([int(i)], float(w[i]), "REPLACE")
    if cfg["cloth"] == "surface":
        carry_on_body(obj, bpy.data.objects["body"])
        return obj, offs
    # Skin weights (they move the pinned waistband / top edge) from the nearest body vertex,
    # restricted to the pelvis and spine: thigh or arm weights would stretch the band.
    keep = np.array([n in torso_bones for n in bone_names])
    dominant = np.argmax(body_w, axis=1)
    torso = np.nonzero(keep[dominant] & (body_w.sum(1) > 0))[0]
    kd = KDTree(len(torso))
    for j, i in enumerate(torso):
        kd.insert(body_rest[i], j)
    kd.balance()
    groups = {}
    for vi, p in enumerate(verts):
        _, j, _ = kd.find(p)
        bw = body_w[torso[j]] * keep
        bw = bw / bw.sum() if bw.sum() > 0 else keep / keep.sum()
        for bi in np.nonzero(bw > 1e-3)[0]:
            name = bone_names[bi]
            if name not in groups:
                groups[name] = obj.vertex_groups.new(name=name)
            groups[name].add([vi], float(bw[bi]), "REPLACE")
    arm = obj.modifiers.new("armature", "ARMATURE")
    arm.object = bpy.data.objects["rig"]
    mod = obj.modifiers.new("cloth", "CLOTH")
    s, c = mod.settings, mod.collision_settings
    inner_a = layer_attrs[0]
    s.quality = cfg["cloth_quality"]
    s.mass = inner_a["mass"]
    # Per-layer stiffness through vertex groups (outfits.stiffness_groups).
    tension_group, s.tension_stiffness, s.tension_stiffness_max = stiffness["tension"]
    s.compression_stiffness, s.compression_stiffness_max = s.tension_stiffness, s.tension_stiffness_max
    bending_group, s.bending_stiffness, s.bending_stiffness_max = stiffness["bending"]
    s.vertex_group_structural_stiffness = tension_group
    s.vertex_group_bending = bending_group
    s.vertex_group_mass = "pin"
    c.use_collision = True
    c.distance_min = cfg["distance_body"]
    c.use_self_collision = True
    c.self_distance_min = cfg["distance_self"]
    c.self_friction = inner_a["self_friction"]
    c.vertex_group_self_collisions = "no_self_collision"
    mod.point_cache.frame_start = 1
    mod.point_cache.frame_end = cfg["frames"]
    return obj, offs


def main():
    args, cfg = parse_args()
    t_start = time.time()
    rng = np.random.default_rng(args.seed)
    T = cfg["frames"]
    clip, bvh_start, speed = sample_motion(rng, cfg, args.split)
    yaw = float(rng.uniform(*cfg["yaw_range_deg"]))
    mirror = bool(rng.random() < cfg["mirror_probability"])
    abduction = float(rng.uniform(*cfg["arm_abduction_deg"]))
    if cfg["heldout_kinds"]:
        inner_kind, outer_kind = sample_outfit_kinds(rng, cfg, args.split)
    else:
        inner_kind = str(rng.choice(cfg["inner_kinds"]))
        outer_kind = str(rng.choice(cfg["outer_kinds"]))
    layer_attrs, body_friction = outfits.sample_attributes(rng, cfg["ranges"])
    pivots = sample_wind(rng, cfg, T)
    for p in pivots:
        p["strength"] *= float(cfg["wind_scale"])
    warp = sample_time_warp(rng, cfg)
    # Procedural overlays draw from their own generator: every other draw stays as it was.
    procedural = motion_blocks.sample_procedural(np.random.default_rng([args.seed, 1]), cfg["procedural"], T,
                                            1 + cfg["rest_frames"] + cfg["ramp_frames"]) if cfg["procedural"] else None
    pose_blend = float(rng.uniform(*cfg["pose_blend_range"])) if cfg["pose_blend_range"][0] < 1 else 1.0
    skel = body_rig.skeleton_of(clip)
    steps = [body_rig.bvh_rate(clip) / 30.0 * speed * u for u in warp]

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 30
    scene.gravity = (0.0, 0.0, -9.8)
    scene.frame_start, scene.frame_end = 1, T
    body = body_rig.import_body(cfg["decimate_ratio"])
    mocap = body_rig.import_bvh(clip)
    rig = body_rig.build_rig(mocap, body, skel)
    body_w, bone_names = body_rig.bind_body(body, rig, skel, cfg["leg_spread_deg"])
    body_rest = body_rig._mesh_world(body)
    unweighted = int((body_w.sum(1) <= 0).sum())
    ramp_start = 1 + cfg["rest_frames"]
    body_rig.retime_mocap(mocap, rig, skel, bvh_start, ramp_start, steps, cfg["time_warp_segment_frames"], yaw,
                          abduction)
    if procedural:
        body_rig.overlay_procedural(mocap, skel, procedural, T)
    body_rig.drive_rig(rig, mocap, ramp_start, cfg["ramp_frames"], pose_blend)
    body.modifiers.new("collision", "COLLISION")
    body.collision.cloth_friction = body_friction

    profile = BodyProfile(body_rest, centre=(0.0, -0.03 * SCENE_SCALE), arm_x=0.35 * SCENE_SCALE)
    garments = outfits.build_outfit(profile, inner_kind, outer_kind, rng, cfg["garment_spacing_m"],
                                    cfg["ring_vertices"])
    cloth, offs = make_cloth(garments, body_w, bone_names, body_rest, layer_attrs, cfg, skel.torso)
    add_wind(pivots, (0.0, 0.0, 1.0 * SCENE_SCALE), cfg["field_seed"], float(cfg["wind_field_factor"]))

    body_faces = body_rig.triangles(body)
    # Faces must wind counter-clockwise seen from outside: check the signed volume.
    a, b, c = (body_rest[body_faces[:, k]] for k in range(3))
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0:
        body_faces = body_faces[:, [0, 2, 1]]

    t_setup = time.time() - t_start
    B, N = len(body.data.vertices), offs[-1]
    body_v = np.zeros((T, B, 3))
    cloth_v = np.zeros((T, N, 3))
    trans = np.zeros((T, 3))
    t0, c0 = time.time(), time.process_time()
    frame_s = []
    for f in range(T):
        tf = time.time()
        scene.frame_set(f + 1)
        dg = bpy.context.evaluated_depsgraph_get()
        body_v[f] = body_rig.body_mesh_frame(body, dg)
        cloth_v[f] = body_rig._mesh_world_eval(cloth.evaluated_get(dg))
        trans[f] = np.array(rig.matrix_world @ rig.pose.bones["Hips"].head)
        frame_s.append(time.time() - tf)
    t_sim = time.time() - t0
    cpu_sim = time.process_time() - c0   # all Blender threads; not inflated by other jobs
    load = os.getloadavg()[0]

    wind_rot, wind_strength = wind_arrays(pivots, T)
    gar = []
    for i, g in enumerate(garments):
        gar.append({"name": g.name, "type": g.kind, "vertices": cloth_v[:, offs[i]:offs[i + 1]],
                    "faces": g.faces, "uv": g.uv, "panel": g.panel, "rest": g.verts,
                    "pin": g.pin, "attrs": layer_attrs[i]})
    if mirror:
        # Mirror x: a mirrored motion with mirrored garments is as physical as the original.
        flip = np.array([-1.0, 1.0, 1.0])
        body_v, trans = body_v * flip, trans * flip
        body_faces = body_faces[:, [0, 2, 1]]
        for g in gar:
            g["vertices"], g["rest"] = g["vertices"] * flip, g["rest"] * flip
            g["faces"] = g["faces"][:, [0, 2, 1]]
            g["uv"] = g["uv"][:, [0, 2, 1]]
        wind_rot = wind_rot * np.array([1.0, 1.0, -1.0, -1.0])

    t1 = time.time()
    q = quality.gates(body_v, body_faces, gar, ramp_start - 1)
    t_gates = time.time() - t1
    finite = bool(np.isfinite(cloth_v).all() and np.isfinite(body_v).all())
    max_wind = float(wind_strength.max())
    tags = {"inner": "tight" if inner_kind in outfits.TIGHT_INNER else "loose",
            "wind": "windy" if max_wind > 250 else ("calm" if max_wind <= 50 else "moderate")}
    if cfg["heldout_kinds"]:
        tags["outfit"] = "unseen" if {inner_kind, outer_kind} & set(cfg["heldout_kinds"]) else "seen"
    if cfg["procedural"]:
        tags["motion"] = "procedural" if procedural and procedural["active"] else "mocap"
    report = {
        "seed": args.seed, "split": args.split, "clip": clip, "bvh_start": bvh_start, "speed": speed,
        "yaw_deg": yaw, "mirrored": mirror, "arm_abduction_deg": abduction, "skeleton": skel.name,
        "time_warp": warp, "pose_blend": pose_blend, "procedural": procedural,
        "wind_field_factor": float(cfg["wind_field_factor"]), "stiffness_groups": cfg["stiffness_groups"],
        "inner_kind": inner_kind, "outer_kind": outer_kind, "garments": [g["name"] for g in gar],
        "garment_types": [g["type"] for g in gar], "attributes": layer_attrs,
        "body_friction": body_friction, "wind_pivots": pivots, "max_wind_strength": max_wind,
        **({"cloth_source": "surface_deform"} if cfg["cloth"] == "surface" else {}),
        "tags": tags, "frames": T, "rest_frames": cfg["rest_frames"], "ramp_frames": cfg["ramp_frames"],
        "body_vertices": B, "cloth_vertices": int(N), "unweighted_body_vertices": unweighted,
        "finite": finite, "quality": q,
        "timing": {"setup_s": t_setup, "simulate_s": t_sim, "blender_s_per_frame": t_sim / T,
                   "gates_s": t_gates, "frame_s": frame_s,
                   "blender_cpu_s_per_frame": cpu_sim / T, "load_average_1min": load},
    }
    extra = {"generator": "layersnet generate (Blender cloth, generate/make_sequence.py)",
             "seed": args.seed, "split": args.split, "tag_inner": tags["inner"], "tag_wind": tags["wind"],
             "clip": clip, "bvh_start": bvh_start, "speed": speed, "yaw_deg": yaw,
             "mirrored": int(mirror), "rest_frames": cfg["rest_frames"], "ramp_frames": cfg["ramp_frames"],
             "max_wind_strength": max_wind, "q_blender_s_per_frame": t_sim / T}
    for k, v in q.items():
        extra["q_" + k] = v
    if cfg["cloth"] == "surface":
        extra["generator"] = ("layersnet generate (garments carried by the body through Blender's Surface Deform, "
                              "no cloth solver: not simulated cloth; generate/make_sequence.py)")
        extra["cloth_source"] = "surface_deform"
    if cfg["wind_field_factor"] != 1.0:
        extra["wind_field_factor"] = float(cfg["wind_field_factor"])
    if cfg["stiffness_groups"] != "outer_max":
        extra["stiffness_groups"] = cfg["stiffness_groups"]
    if "outfit" in tags:
        extra["tag_outfit"] = tags["outfit"]
    if "motion" in tags:
        extra["tag_motion"] = tags["motion"]
    seq = {"fps": 30.0, "gravity": (0.0, 0.0, -9.8), "scale": SCENE_SCALE,
           "body": {"vertices": body_v, "faces": body_faces, "translation": trans, "friction": body_friction},
           "garments": gar, "wind": {"rotation": wind_rot, "strength": wind_strength}, "extra_attrs": extra}
    if finite:
        write_sequence(args.out, seq)
    report["timing"]["total_s"] = time.time() - t_start
    tmp = args.report + ".tmp"
    with open(tmp, "w") as f:
        json.dump(report, f, indent=1)
    os.replace(tmp, args.report)
    print(f"make_sequence: seed {args.seed} {inner_kind}+{outer_kind} {clip}@{bvh_start:.0f} "
          f"B={B} N={N} sim {t_sim / T:.3f} s/frame gates {q}", flush=True)


if __name__ == "__main__":
    try:
        main()
    except SystemExit:
        raise
    except Exception:
        import traceback
        traceback.print_exc()
        sys.exit(1)
