"""A BVH clip on the generator's body, as body frames for `layersnet simulate --motion` (bpy).

The same road as `layersnet generate` (body_rig.py): the MakeHuman body, decimated and bound
to a copy of the clip's skeleton moved onto the body's joints, driven by the clip with
world-space rotation copies that ramp in from the rest pose. Frame 0 is the rest pose the
garments are modelled on (the generator's rest frames), then `--ramp-frames` frames blend into
the clip, which plays from BVH frame `--bvh-start` resampled to `--fps` (the clip's own rate
is read from its 'Frame Time:' line).

Writes OUT/body.obj (the rest-pose mesh: v and f lines) and OUT/body.pc2 (every frame), in the
caller's units and axes: `--scale` units per metre, `--up z|y`. Run inside Blender:
  blender -b --factory-startup --python-exit-code 1 --python generate/retarget_bvh.py -- \
      CLIP.bvh OUT [--bvh-start 1] [--frames 0] [--fps 30] [--scale 10] [--up z]
Exit status 3 with one line "retarget_bvh: error: CLIP: ..." when the clip cannot be used.
"""
import argparse
import os
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import body_rig  # noqa: E402
import motion_blocks  # noqa: E402
from garments import SCENE_SCALE  # noqa: E402

# As the generator's default recipe (make_sequence.py DEFAULTS): the rest pose the garments
# of generated data are modelled on, and arms raised so hanging hands do not trap skirts.
DECIMATE_RATIO = 0.3
LEG_SPREAD_DEG = 7.0
ARM_ABDUCTION_DEG = 25.0


def fail(clip, what):
    print(f"retarget_bvh: error: {clip}: {what}", flush=True)
    sys.exit(3)


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("clip")
    p.add_argument("out")
    p.add_argument("--bvh-start", type=int, default=1, help="first BVH frame played (CMU frame 0 is a calibration pose)")
    p.add_argument("--frames", type=int, default=0, help="body frames to write (0 = up to the clip's end)")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second of the written motion")
    p.add_argument("--ramp-frames", type=int, default=15, help="frames from the rest pose into the clip")
    p.add_argument("--yaw", type=float, default=0.0, help="turn the clip about the up axis (degrees)")
    p.add_argument("--scale", type=float, default=SCENE_SCALE, help="output units per metre")
    p.add_argument("--up", choices=("z", "y"), default="z", help="up axis of the output files")
    return p.parse_args(argv)


def write_pc2(path, frames):
    """PC2: 'POINTCACHE2\\0', version 1, points, start frame 0, sample rate 1, samples; float32 xyz."""
    frames = np.ascontiguousarray(frames, dtype="<f4")
    with open(path, "wb") as f:
        f.write(b"POINTCACHE2\0" + struct.pack("<iiffi", 1, frames.shape[1], 0.0, 1.0, frames.shape[0]))
        f.write(frames.tobytes())


def write_obj(path, v, faces):
    with open(path, "w") as out:
        out.writelines("v %.9g %.9g %.9g\n" % tuple(p) for p in v)
        out.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in faces)


def to_caller_units(x, scale, up):
    """Scene coordinates (x10, z up) to `scale` units per metre with `up` up (the inverse of
    simulate's reading conversion: for y up, input (x, y, z) is scene (x, -z, y))."""
    x = x * (scale / SCENE_SCALE)
    return x if up == "z" else np.stack([x[..., 0], x[..., 2], -x[..., 1]], axis=-1)


def main():
    a = parse_args()
    clip = os.path.abspath(a.clip)
    try:
        skel = body_rig.skeleton_of(clip)
    except SystemExit:
        fail(clip, f"unknown skeleton (joints {', '.join(body_rig.bvh_joints(clip))}): --motion takes the skeleton "
                   "of the CMU motion-capture library (31 joints, Hips to the fingers) or of assimp's Boxing_Toes; "
                   "another skeleton needs its bones mapped in generate/body_rig.py (Skeleton)")
    count = motion_blocks.bvh_frame_count(clip, "/")
    if not 0 <= a.bvh_start < count:
        fail(clip, f"--bvh-start {a.bvh_start} is outside its {count} frames (0..{count - 1})")
    step = body_rig.bvh_rate(clip) / a.fps  # BVH frames per written frame
    ramp_start = 2  # scene frame 1 is the rest pose (Blender counts frames from 1)
    frames = a.frames if a.frames > 0 else ramp_start + int((count - 1 - a.bvh_start) / step)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = int(round(a.fps))
    scene.frame_start, scene.frame_end = 1, frames
    body = body_rig.import_body(DECIMATE_RATIO)
    mocap = body_rig.import_bvh(clip)
    rig = body_rig.build_rig(mocap, body, skel)
    body_rig.bind_body(body, rig, skel, LEG_SPREAD_DEG)
    rest = body_rig._mesh_world(body)
    body_rig.retime_mocap(mocap, rig, skel, a.bvh_start, ramp_start, [step], frames + 1, a.yaw, ARM_ABDUCTION_DEG)
    body_rig.drive_rig(rig, mocap, ramp_start, a.ramp_frames)
    faces = body_rig.triangles(body)
    a_, b_, c_ = (rest[faces[:, k]] for k in range(3))
    if np.einsum("ij,ij->i", a_, np.cross(b_, c_)).sum() < 0:  # counter-clockwise seen from outside
        faces = faces[:, [0, 2, 1]]

    out = np.empty((frames, len(rest), 3))
    for f in range(frames):
        scene.frame_set(f + 1)
        out[f] = body_rig.body_mesh_frame(body, bpy.context.evaluated_depsgraph_get())
        if (f + 1) % 50 == 0 or f + 1 == frames:
            print(f"retarget_bvh: frame {f + 1}/{frames}", flush=True)
    if not np.isfinite(out).all():
        fail(clip, "the retargeted body has non-finite positions (a corrupt motion section?)")
    os.makedirs(a.out, exist_ok=True)
    write_obj(os.path.join(a.out, "body.obj"), to_caller_units(out[0], a.scale, a.up), faces)
    write_pc2(os.path.join(a.out, "body.pc2"), to_caller_units(out, a.scale, a.up))
    print(f"retarget_bvh: {clip} ({skel.name} skeleton, {body_rig.bvh_rate(clip):g} Hz) from BVH frame {a.bvh_start}: "
          f"{frames} frames at {a.fps:g} fps, {len(rest)} body vertices -> {a.out}", flush=True)


if __name__ == "__main__":
    main()
