"""The MakeHuman body from assimp-testmodels, skinned to a mocap skeleton (bpy).

Recipe: import the Collada body
(z up after import, faces -y, feet at z = 0), decimate it, scale the world x10; import
the BVH clip (CMU clips, or Boxing_Toes with its own skeleton: `Skeleton`); copy its
armature as the rig, move the rig's joints onto the body's
A-pose joints (landmarks measured on this mesh), bind the body with bone-heat weights,
then drive the rig from the mocap with world-space copy-rotation constraints whose
influence ramps 0 -> 1, so garments start around the rest-pose body.
"""
import builtins
import math
import os
import tempfile
import zipfile

import bpy
import mathutils
import numpy as np

import motion_blocks
from garments import SCENE_SCALE

HUMAN_ZAE = "/usr/share/assimp/models/Collada/human.zae"
BVH_DIR = motion_blocks.BVH_DIR
S = SCENE_SCALE

# A-pose joint landmarks of the MakeHuman test body (metres, left side; the right side
# mirrors x). Measured from cross-sections of the mesh; limb joints are refined to the
# local centroid of the surface at run time.
_L = {
    "Hips": ((0, -0.03, 0.93), (0, -0.03, 0.98)),
    "LHipJoint": ((0, -0.03, 0.93), (0.09, -0.03, 0.88)),
    "LeftUpLeg": ((0.09, -0.03, 0.88), (0.14, -0.03, 0.48)),
    "LeftLeg": ((0.14, -0.03, 0.48), (0.185, -0.02, 0.08)),
    "LeftFoot": ((0.185, -0.02, 0.08), (0.19, -0.10, 0.025)),
    "LeftToeBase": ((0.19, -0.10, 0.025), (0.19, -0.18, 0.015)),
    "LowerBack": ((0, -0.03, 0.93), (0, -0.03, 1.05)),
    "Spine": ((0, -0.03, 1.05), (0, -0.03, 1.20)),
    "Spine1": ((0, -0.03, 1.20), (0, -0.03, 1.36)),
    "Neck": ((0, -0.02, 1.36), (0, -0.02, 1.45)),
    "Neck1": ((0, -0.02, 1.45), (0, -0.03, 1.53)),
    "Head": ((0, -0.03, 1.53), (0, -0.03, 1.66)),
    "LeftShoulder": ((0.03, -0.02, 1.36), (0.17, -0.02, 1.34)),
    "LeftArm": ((0.17, -0.02, 1.30), (0.36, -0.04, 1.10)),
    "LeftForeArm": ((0.36, -0.04, 1.10), (0.44, -0.16, 1.00)),
    "LeftHand": ((0.44, -0.16, 1.00), (0.49, -0.27, 0.95)),
    "LeftFingerBase": ((0.47, -0.22, 0.97), (0.49, -0.27, 0.95)),
    "LFingers": ((0.49, -0.27, 0.95), (0.50, -0.31, 0.93)),
    "LThumb": ((0.45, -0.20, 0.99), (0.46, -0.25, 0.98)),
}
_REFINE = ("LeftLeg", "LeftFoot", "LeftForeArm", "LeftHand")  # heads snapped to local centroid


def _mirror_name(name):
    return name.replace("Left", "Right").replace("LHip", "RHip").replace("LFingers", "RFingers") \
        .replace("LThumb", "RThumb")


class Skeleton:
    """A mocap skeleton described with the CMU bones the landmarks are measured for.

    landmark_of: bone -> (CMU bone giving its head, CMU bone giving its tail);
    metres_per_unit: BVH length unit in metres on the MakeHuman body (hip to ankle 0.80 m);
    torso: the bones that may move garment pins (pelvis and spine)."""

    def __init__(self, name, left_and_centre, metres_per_unit, torso):
        self.name, self.metres_per_unit, self.torso = name, metres_per_unit, tuple(torso)
        self.landmark_of = dict(left_and_centre)
        for bone, (head, tail) in left_and_centre.items():
            if "Left" in bone:
                self.landmark_of[bone.replace("Left", "Right")] = (_mirror_name(head), _mirror_name(tail))

    def bone(self, cmu_bone):
        """This skeleton's bone that spans exactly the CMU bone `cmu_bone` (a limb)."""
        return next(b for b, ends in self.landmark_of.items() if ends == (cmu_bone, cmu_bone))


CMU_SKELETON = Skeleton(
    "cmu", {name: (name, name) for name in list(_L) + [_mirror_name(n) for n in _L]}, 0.80 / 13.8,
    ("Hips", "LowerBack", "Spine", "Spine1"))
# Boxing_Toes (assimp-testmodels, 100 Hz): 5 spine/head bones instead of 7, no hip joints or
# fingers; its hip to ankle is 42.22 + 43.43 units.
BOXING_SKELETON = Skeleton("boxing", {
    "Hips": ("Hips", "Hips"), "Ab": ("LowerBack", "Spine"), "Chest": ("Spine1", "Spine1"),
    "Neck": ("Neck", "Neck1"), "Head": ("Head", "Head"),
    "LeftCollar": ("LeftShoulder", "LeftShoulder"), "LeftShoulder": ("LeftArm", "LeftArm"),
    "LeftElbow": ("LeftForeArm", "LeftForeArm"), "LeftWrist": ("LeftHand", "LFingers"),
    "LeftHip": ("LeftUpLeg", "LeftUpLeg"), "LeftKnee": ("LeftLeg", "LeftLeg"),
    "LeftAnkle": ("LeftFoot", "LeftFoot"), "LeftToes": ("LeftToeBase", "LeftToeBase"),
}, 0.80 / (42.224018 + 43.430279), ("Hips", "Ab", "Chest"))


def bvh_joints(clip):
    names = []
    with open(os.path.join(BVH_DIR, clip)) as f:
        for line in f:
            word = line.split()
            if word and word[0] in ("ROOT", "JOINT"):
                names.append(word[1])
            if word and word[0] == "MOTION":
                break
    return names


def skeleton_of(clip):
    joints = set(bvh_joints(clip))
    for skel in (CMU_SKELETON, BOXING_SKELETON):
        if joints == set(skel.landmark_of):
            return skel
    raise SystemExit(f"{clip}: unknown skeleton (joints {sorted(joints)}); add a Skeleton in body_rig.py")


def bvh_rate(clip):
    """Frames per second of a BVH clip, from its 'Frame Time:' line (rounded: files write
    the frame time to few digits, e.g. .0083333 for 120 Hz)."""
    with open(os.path.join(BVH_DIR, clip)) as f:
        for line in f:
            if line.startswith("Frame Time:"):
                return round(1.0 / float(line.split()[2]), 2)
    raise RuntimeError(f"{clip}: no 'Frame Time:' line")


def landmarks():
    """CMU bone -> (head, tail) in metres for every bone of the CMU skeleton."""
    out = {}
    for name, (h, t) in _L.items():
        out[name] = (np.array(h, float), np.array(t, float))
        m = _mirror_name(name)
        if m != name:
            out[m] = (np.array(h, float) * [-1, 1, 1], np.array(t, float) * [-1, 1, 1])
    return out


def _mesh_world(obj):
    n = len(obj.data.vertices)
    co = np.empty(n * 3)
    obj.data.vertices.foreach_get("co", co)
    w = np.array(obj.matrix_world)
    return co.reshape(-1, 3) @ w[:3, :3].T + w[:3, 3]


def import_body(decimate_ratio):
    """The decimated body at x10 scale, transforms applied. Returns the mesh object."""
    with tempfile.TemporaryDirectory(prefix="layersnet_body_") as tmp:  # gone once imported
        with zipfile.ZipFile(HUMAN_ZAE) as z:
            z.extract("human.dae", tmp)
        bpy.ops.wm.collada_import(filepath=os.path.join(tmp, "human.dae"))
    body = bpy.data.objects["human-base"]
    for o in list(bpy.data.objects):
        if o is not body:
            bpy.data.objects.remove(o, do_unlink=True)
    bpy.context.view_layer.objects.active = body
    body.select_set(True)
    body.parent = None
    body.matrix_world = mathutils.Matrix.Scale(S, 4) @ body.matrix_world
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    mod = body.modifiers.new("decimate", "DECIMATE")
    mod.ratio = decimate_ratio
    bpy.ops.object.modifier_apply(modifier=mod.name)
    body.name = "body"
    return body


def import_bvh(clip):
    """Imports a BVH clip at the body's scale (x10). Returns the armature object."""
    import io_anim_bvh.import_bvh as import_bvh
    # This Blender's importer opens files with mode 'rU', which Python 3.11 rejects.
    import_bvh.open = lambda p, mode="r", *a, **k: builtins.open(p, mode.replace("U", ""), *a, **k)
    bpy.ops.import_anim.bvh(filepath=os.path.join(BVH_DIR, clip), global_scale=skeleton_of(clip).metres_per_unit * S,
                            rotate_mode="NATIVE", update_scene_fps=False, update_scene_duration=False)
    arm = bpy.context.view_layer.objects.active
    arm.name = "mocap"
    return arm


def build_rig(mocap, body, skel):
    """A copy of the mocap armature with its joints moved onto the body's A-pose joints."""
    rig = mocap.copy()
    rig.data = mocap.data.copy()
    rig.animation_data_clear()
    rig.name = "rig"
    # The copy keeps the mocap's current pose values (hips location of the clip): clear them.
    for pb in rig.pose.bones:
        pb.location = (0.0, 0.0, 0.0)
        pb.rotation_euler = (0.0, 0.0, 0.0)
        pb.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
        pb.scale = (1.0, 1.0, 1.0)
    bpy.context.scene.collection.objects.link(rig)
    verts = _mesh_world(body)
    lm = landmarks()
    for base in _REFINE:
        for name in (base, _mirror_name(base)):
            head = lm[name][0] * S
            for _ in range(3):
                near = verts[np.linalg.norm(verts - head, axis=1) < 0.05 * S]
                if len(near) > 10:
                    head = near.mean(0)
            lm[name] = (head / S, lm[name][1])
            parent = {"LeftLeg": "LeftUpLeg", "LeftFoot": "LeftLeg", "LeftForeArm": "LeftArm",
                      "LeftHand": "LeftForeArm"}[base]
            pname = parent if name == base else _mirror_name(parent)
            lm[pname] = (lm[pname][0], head / S)
    lm = {bone: (lm[first][0], lm[last][1]) for bone, (first, last) in skel.landmark_of.items()}
    bpy.ops.object.select_all(action="DESELECT")
    bpy.context.view_layer.objects.active = rig
    rig.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    for eb in rig.data.edit_bones:
        if eb.name in lm:
            # Rotate the mocap's rest frame by the smallest rotation taking its bone direction
            # onto the body's: the rig keeps the mocap's roll, so world-space rotation copies
            # give the mocap pose without twisting the limbs.
            h, t = (mathutils.Vector(x * S) for x in lm[eb.name])
            d_cur = (eb.tail - eb.head).normalized()
            q = d_cur.rotation_difference((t - h).normalized())
            m = (q.to_matrix() @ eb.matrix.to_3x3()).to_4x4()
            m.translation = h
            eb.use_connect = False
            eb.length = (t - h).length
            eb.matrix = m
    bpy.ops.object.mode_set(mode="OBJECT")
    return rig


def _spread_legs(body, rig, deg, skel):
    """Turns both thighs outwards by `deg` and makes that the rest pose of body and rig:
    the MakeHuman thighs touch below the crotch, which leaves no room for trouser legs."""
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="POSE")
    for name, axis in (("LeftUpLeg", (0, -1, 0)), ("RightUpLeg", (0, 1, 0))):
        pb = rig.pose.bones[skel.bone(name)]
        local_axis = pb.bone.matrix_local.to_3x3().inverted() @ mathutils.Vector(axis)
        rot = mathutils.Matrix.Rotation(math.radians(deg), 3, local_axis)
        if pb.rotation_mode == "QUATERNION":
            pb.rotation_quaternion = rot.to_quaternion()
        else:
            pb.rotation_euler = rot.to_euler(pb.rotation_mode)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.update()
    bpy.ops.object.select_all(action="DESELECT")
    bpy.context.view_layer.objects.active = body
    body.select_set(True)
    arm_mod = next(m for m in body.modifiers if m.type == "ARMATURE")
    bpy.ops.object.modifier_apply(modifier=arm_mod.name)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="POSE")
    bpy.ops.pose.select_all(action="SELECT")
    bpy.ops.pose.armature_apply(selected=False)
    bpy.ops.object.mode_set(mode="OBJECT")
    mod = body.modifiers.new("Armature", "ARMATURE")
    mod.object = rig


def bind_body(body, rig, skel, leg_spread_deg=0.0):
    """Bone-heat weights; returns (B, nbones) weights and the bone names."""
    bpy.ops.object.select_all(action="DESELECT")
    body.select_set(True)
    rig.select_set(True)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.parent_set(type="ARMATURE_AUTO")
    if leg_spread_deg:
        _spread_legs(body, rig, leg_spread_deg, skel)
    names = [b.name for b in rig.data.bones]
    w = np.zeros((len(body.data.vertices), len(names)))
    gidx = {g.index: names.index(g.name) for g in body.vertex_groups if g.name in names}
    for v in body.data.vertices:
        for g in v.groups:
            if g.group in gidx:
                w[v.index, gidx[g.group]] = g.weight
    return w, names


def retime_mocap(mocap, rig, skel, bvh_start, scene_start, steps, segment_frames, yaw_deg, arm_abduction_deg):
    """Plays BVH frame `bvh_start` at scene frame `scene_start` and on through the time map
    (`scene_frames_of`: speed and time warps); rotates the clip about z by `yaw_deg` around
    its hips at that frame, moves it so its hips start on the rig's hips, and raises both
    upper arms by `arm_abduction_deg` so hanging hands do not trap skirts and coats against
    the hips."""
    action = mocap.animation_data.action
    for fc in action.fcurves:
        n = len(fc.keyframe_points)
        co = np.empty(2 * n)
        fc.keyframe_points.foreach_get("co", co)
        co = co.reshape(-1, 2)
        co[:, 0] = motion_blocks.scene_frames_of(co[:, 0], bvh_start, scene_start, steps, segment_frames)
        fc.keyframe_points.foreach_set("co", co.ravel())
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
        fc.update()
    _abduct_arms(mocap, arm_abduction_deg, skel)
    scene = bpy.context.scene
    scene.frame_set(scene_start)
    hips = mocap.matrix_world @ mocap.pose.bones["Hips"].head
    rot = mathutils.Matrix.Rotation(math.radians(yaw_deg), 4, "Z")
    target = rig.matrix_world @ rig.data.bones["Hips"].head_local
    mocap.matrix_world = mathutils.Matrix.Translation(target) @ rot @ \
        mathutils.Matrix.Translation(-hips) @ mocap.matrix_world
    bpy.context.view_layer.update()


def _rotate_arm_keys(mocap, skel, arms):
    """Left-multiplies the local rotation of each upper arm at every key by a rotation about a
    world axis of the rest frame. arms: (CMU bone name, world axis, angle_at(key frame) in
    radians)."""
    action = mocap.animation_data.action
    for cmu_name, axis, angle_at in arms:
        name = skel.bone(cmu_name)
        pb = mocap.pose.bones[name]
        rest = pb.bone.matrix_local.to_3x3()
        local_axis = rest.inverted() @ mathutils.Vector(axis)
        path = f'pose.bones["{name}"].rotation_euler'
        fcs = [action.fcurves.find(path, index=i) for i in range(3)]
        n = len(fcs[0].keyframe_points)
        cos = []
        for fc in fcs:
            c = np.empty(2 * n)
            fc.keyframe_points.foreach_get("co", c)
            cos.append(c.reshape(-1, 2))
        order = pb.rotation_mode
        for k in range(n):
            q = mathutils.Matrix.Rotation(angle_at(cos[0][k, 0]), 3, local_axis)
            e = mathutils.Euler((cos[0][k, 1], cos[1][k, 1], cos[2][k, 1]), order)
            e2 = (q @ e.to_matrix()).to_euler(order, e)
            for i in range(3):
                cos[i][k, 1] = e2[i]
        for fc, c in zip(fcs, cos):
            fc.keyframe_points.foreach_set("co", c.ravel())
            fc.update()


def _abduct_arms(mocap, deg, skel):
    """Raises each upper arm sideways by deg about the rest frame's axis that does so (world -y
    for the left arm, +y for the right)."""
    angle = math.radians(deg)
    _rotate_arm_keys(mocap, skel, [("LeftArm", (0, -1, 0), lambda f: angle),
                                   ("RightArm", (0, 1, 0), lambda f: angle)])


def drive_rig(rig, mocap, ramp_start, ramp_frames, pose_blend=1.0):
    """World-space copy-rotation constraints (and copy-location on the hips) from the
    mocap, with influence 0 before `ramp_start` rising linearly over `ramp_frames` to 1 for
    the location and to `pose_blend` for the rotations (below 1: a blend of the mocap with the
    rest pose, a smaller motion)."""
    for pb in rig.pose.bones:
        kinds = ["COPY_ROTATION"] + (["COPY_LOCATION"] if pb.name == "Hips" else [])
        for kind in kinds:
            c = pb.constraints.new(kind)
            c.target = mocap
            c.subtarget = pb.name
            c.target_space = "WORLD"
            c.owner_space = "WORLD"
            c.influence = 0.0
            c.keyframe_insert("influence", frame=ramp_start)
            c.influence = pose_blend if kind == "COPY_ROTATION" else 1.0
            c.keyframe_insert("influence", frame=ramp_start + ramp_frames)
    for fc in rig.animation_data.action.fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def body_mesh_frame(body, depsgraph):
    """(B, 3) evaluated body vertices in world coordinates."""
    ev = body.evaluated_get(depsgraph)
    return _mesh_world_eval(ev)


def _mesh_world_eval(ev):
    me = ev.data
    n = len(me.vertices)
    co = np.empty(n * 3)
    me.vertices.foreach_get("co", co)
    w = np.array(ev.matrix_world)
    return co.reshape(-1, 3) @ w[:3, :3].T + w[:3, 3]


def triangles(obj):
    """(F, 3) triangles of a mesh object (its polygons fan-triangulated by Blender)."""
    me = obj.data
    me.calc_loop_triangles()
    n = len(me.loop_triangles)
    tri = np.empty(n * 3, np.int64)
    me.loop_triangles.foreach_get("vertices", tri)
    return tri.reshape(-1, 3)


def overlay_procedural(mocap, skel, proc, frames):
    """Applies `sample_procedural`'s overlays to the (retimed, placed) mocap object: the clip
    turns about the vertical through its hips by yaw_deg[f] at stored frame f, its travel turns
    with it (a walk that turns), hops lift it, and the upper arms swing forward and back.
    Keyed per scene frame (the rig copies the mocap in world space)."""
    if not proc or not proc["active"]:
        return
    if proc["arm_swing"]:
        _swing_arms(mocap, skel, proc["arm_swing"])
    scene = bpy.context.scene
    m0 = mocap.matrix_world.copy()
    hips = []
    for f in range(frames):
        scene.frame_set(f + 1)
        hips.append(m0 @ mocap.pose.bones["Hips"].head)
    yaw = proc["yaw_deg"]
    lift = proc["lift_m"]
    pos = hips[0].copy()
    mocap.rotation_mode = "QUATERNION"
    prev = None
    for f in range(frames):
        if f > 0:
            step = hips[f] - hips[f - 1]
            pos = pos + mathutils.Matrix.Rotation(math.radians(yaw[f - 1]), 3, "Z") @ step
        target = pos + mathutils.Vector((0.0, 0.0, lift[f] * S))
        m = mathutils.Matrix.Translation(target) @ mathutils.Matrix.Rotation(math.radians(yaw[f]), 4, "Z") @ \
            mathutils.Matrix.Translation(-hips[f]) @ m0
        loc, rot, scale = m.decompose()
        if prev is not None and prev.dot(rot) < 0:
            rot = -rot
        prev = rot
        mocap.location, mocap.rotation_quaternion, mocap.scale = loc, rot, scale
        for path in ("location", "rotation_quaternion", "scale"):
            mocap.keyframe_insert(path, frame=f + 1)
    for fc in mocap.animation_data.action.fcurves:
        if fc.data_path in ("location", "rotation_quaternion", "scale"):
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"
    scene.frame_set(1)


def _swing_arms(mocap, skel, swing):
    """Swings each upper arm about the body's left-right axis (world x in the rest frame) by
    deg * sin(2 pi hz t + phase), t in seconds of scene time from the overlay's start (0 before
    it); the right arm in opposite phase when `opposite` (a walking swing), else in phase."""
    def angle_at(sign):
        def at(frame):
            t = max(0.0, (frame - swing["start_frame"]) / 30.0)
            ramp = min(1.0, t / 0.3)   # eases in over 0.3 s so the arms do not jump
            return math.radians(swing["deg"]) * ramp * sign * math.sin(2 * math.pi * swing["hz"] * t + swing["phase"])
        return at
    right = -1.0 if swing["opposite"] else 1.0
    _rotate_arm_keys(mocap, skel, [("LeftArm", (1.0, 0.0, 0.0), angle_at(1.0)),
                                   ("RightArm", (1.0, 0.0, 0.0), angle_at(right))])