"""Quality gates of a simulated sequence (numpy + mathutils, runs inside Blender).

- inside_body_share: share of garment vertex-frames whose nearest point on the body
  surface has the vertex behind its face (outward normals), i.e. inside the body.
- outer_inside_inner_share: the same for outer-layer vertices against the inner layer's
  surface, counted only within 0.5 scene units (5 cm) of it: farther than that the
  nearest inner face says nothing about which side the vertex is on (e.g. a coat
  between two trouser legs).
- max_edge_stretch / p99_edge_stretch: edge length over rest length minus 1; the maximum
  and the 99th percentile over all (edge, frame) pairs of a garment, worst garment.
"""
import numpy as np
from mathutils import Vector
from mathutils.bvhtree import BVHTree

NEAR_INNER = 0.5  # scene units


def _inside_share(points, verts, faces, max_dist=None):
    tree = BVHTree.FromPolygons(np.asarray(verts, float).tolist(), np.asarray(faces, int).tolist())
    inside = 0
    for p in points:
        hit = tree.find_nearest(Vector(p)) if max_dist is None else tree.find_nearest(Vector(p), max_dist)
        loc, normal = hit[0], hit[1]
        if loc is not None and (Vector(p) - loc).dot(normal) < 0.0:
            inside += 1
    return inside / max(1, len(points))


def edges_of(faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def gates(body_v, body_f, garments, start_frame):
    """body_v: (T, B, 3); garments: list of dicts with 'vertices' (T, N, 3), 'faces',
    'rest' (N, 3), inner first. Frames before start_frame are skipped for the collision
    shares (the garments are still settling). Returns a dict of floats."""
    T = body_v.shape[0]
    frames = range(min(start_frame, T - 1), T)
    inside = []
    for t in frames:
        pts = np.concatenate([g["vertices"][t] for g in garments])
        inside.append(_inside_share(pts, body_v[t], body_f))
    layer = []
    if len(garments) >= 2:
        inner, outer = garments[0], garments[-1]
        for t in frames:
            layer.append(_inside_share(outer["vertices"][t], inner["vertices"][t], inner["faces"], NEAR_INNER))
    stretch_max, stretch_p99 = 0.0, 0.0
    for g in garments:
        e = edges_of(g["faces"])
        rest = np.linalg.norm(g["rest"][e[:, 0]] - g["rest"][e[:, 1]], axis=1)
        ln = np.linalg.norm(g["vertices"][:, e[:, 0]] - g["vertices"][:, e[:, 1]], axis=2)
        s = ln / np.maximum(rest, 1e-9) - 1.0
        stretch_max = max(stretch_max, float(s.max()))
        stretch_p99 = max(stretch_p99, float(np.percentile(s, 99)))
    return {
        "inside_body_share": float(np.mean(inside)),
        "inside_body_share_max_frame": float(np.max(inside)),
        "outer_inside_inner_share": float(np.mean(layer)) if layer else 0.0,
        "outer_inside_inner_share_max_frame": float(np.max(layer)) if layer else 0.0,
        "max_edge_stretch": stretch_max,
        "p99_edge_stretch": stretch_p99,
    }
