"""Blender reads what `layersnet simulate` writes (run by test_simulate.cpp).

    blender -b --factory-startup --python-exit-code 1 --python blender_reads_simulation.py -- OUT GARMENT FRAME...

Imports OUT/GARMENT/GARMENT_0000.obj, plays OUT/GARMENT.pc2 through a Mesh Cache modifier and
prints one line "RESULT <json>": per frame the vertex count and every vertex position of the
evaluated mesh, once through the cache and once from that frame's OBJ imported by itself.
Positions in the files' coordinates (imported without axis conversion).
"""
import json
import os
import sys

import bpy


def import_obj(path):
    before = set(bpy.data.objects)
    bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    (obj,) = set(bpy.data.objects) - before
    return obj


def evaluated_positions(obj):
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    positions = [list(v.co) for v in mesh.vertices]
    return positions


def main(out, garment, frames):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    obj = import_obj(os.path.join(out, garment, "%s_0000.obj" % garment))
    cache = obj.modifiers.new("cache", "MESH_CACHE")
    cache.cache_format = "PC2"
    cache.filepath = os.path.join(out, garment + ".pc2")
    cache.frame_start = 0  # scene frame k shows output frame k
    result = {"cache": {}, "obj": {}, "uv_layers": len(obj.data.uv_layers)}
    for k in frames:
        scene.frame_set(k)
        result["cache"][k] = evaluated_positions(obj)
    for k in frames:
        one = import_obj(os.path.join(out, garment, "%s_%04d.obj" % (garment, k)))
        result["obj"][k] = [list(v.co) for v in one.data.vertices]
    print("RESULT " + json.dumps(result))


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:]
    main(args[0], args[1], [int(a) for a in args[2:]])
