"""A pinned square of cloth in a horizontal wind: the angle it hangs at (Blender check of the
wind calibration, generate/README.md "The wind").

Run inside Blender:
  blender -b --factory-startup -t 1 --python generate/wind_square.py -- \
      --strength 400 [--field-factor F] [--mass 0.5] [--frames 60] [--out result.json]

The square (side `--side` metres, rows `--spacing` metres apart, at the generator's x10
scale) hangs in the x-z plane from its pinned top row; the wind blows along +y, normal to it.
`--strength` is the stored (D-LAYERS-range) strength; Blender's field gets strength x factor,
as in make_sequence.py. The angle is that of the line from the top row's centre to the bottom
row's centre, from the vertical (0: hangs straight, 90: horizontal), averaged over the last
`--average` frames.
"""
import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import make_sequence  # noqa: E402
from garments import SCENE_SCALE  # noqa: E402


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--strength", type=float, required=True)
    p.add_argument("--field-factor", type=float, default=1.0)
    p.add_argument("--mass", type=float, default=0.5)
    p.add_argument("--tension", type=float, default=40.0)
    p.add_argument("--bending", type=float, default=50.0)
    p.add_argument("--side", type=float, default=0.45, help="metres")
    p.add_argument("--spacing", type=float, default=0.045, help="metres between rows")
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--average", type=int, default=10)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 30
    scene.gravity = (0.0, 0.0, -9.8)
    scene.frame_start, scene.frame_end = 1, a.frames
    n = int(round(a.side / a.spacing)) + 1
    e = a.spacing * SCENE_SCALE
    verts = [((i - (n - 1) / 2) * e, 0.0, -j * e) for j in range(n) for i in range(n)]
    faces = []
    for j in range(n - 1):
        for i in range(n - 1):
            v = j * n + i
            faces += [(v, v + 1, v + n + 1), (v, v + n + 1, v + n)]
    me = bpy.data.meshes.new("square")
    me.from_pydata(verts, [], faces)
    me.update()
    obj = bpy.data.objects.new("square", me)
    scene.collection.objects.link(obj)
    vg = obj.vertex_groups.new(name="pin")
    vg.add(list(range(n)), 1.0, "REPLACE")
    mod = obj.modifiers.new("cloth", "CLOTH")
    s = mod.settings
    s.quality = 30
    s.mass = a.mass
    s.tension_stiffness = s.compression_stiffness = a.tension
    s.bending_stiffness = a.bending
    s.vertex_group_mass = "pin"
    mod.point_cache.frame_start, mod.point_cache.frame_end = 1, a.frames
    # The generator's own wind (make_sequence.add_wind, keyed from frame 0 on): direction +y,
    # the quaternion that turns the field's z axis onto +y (horizontal).
    q = [math.cos(math.pi / 4), -math.sin(math.pi / 4), 0.0, 0.0]
    make_sequence.add_wind([{"frame": 0, "rotation": q, "strength": a.strength * a.field_factor}],
                           (0.0, 0.0, 0.0), 1)
    angles = []
    for f in range(1, a.frames + 1):
        scene.frame_set(f)
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        co = np.array([v.co[:] for v in ev.data.vertices]) @ np.array(obj.matrix_world)[:3, :3].T
        top, bottom = co[:n].mean(0), co[-n:].mean(0)
        d = bottom - top
        angles.append(math.degrees(math.atan2(math.hypot(d[0], d[1]), -d[2])))
    result = {"strength": a.strength, "field_factor": a.field_factor, "field_strength": a.strength * a.field_factor,
              "mass": a.mass, "spacing_m": a.spacing, "side_m": a.side, "vertices": n * n,
              "angle_deg": float(np.mean(angles[-a.average:])), "angle_by_frame": angles}
    print("wind_square:", json.dumps({k: v for k, v in result.items() if k != "angle_by_frame"}), flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    try:
        main()
    except SystemExit:
        raise
    except Exception:
        import traceback
        traceback.print_exc()
        sys.exit(1)
