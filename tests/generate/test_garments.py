#!/usr/bin/python3
"""Checks the garment templates without Blender, on a synthetic rest body (ellipsoid torso,
two cylinder legs): panels, metric UVs, outward faces, the outer layer outside the inner."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../generate"))
import outfits  # noqa: E402
from garments import SCENE_SCALE, BodyProfile, top_ring_pin  # noqa: E402

S = SCENE_SCALE


def synthetic_body():
    pts = []
    for z in np.arange(0.0, 1.66, 0.01):
        a = np.linspace(0, 2 * np.pi, 72, endpoint=False)
        if z > 0.84:   # torso
            pts.append(np.stack([0.16 * np.sin(a), -0.03 - 0.11 * np.cos(a), np.full_like(a, z)], 1))
        else:          # legs
            for x in (-0.1, 0.1):
                pts.append(np.stack([x + 0.07 * np.sin(a), -0.03 - 0.07 * np.cos(a), np.full_like(a, z)], 1))
    return np.concatenate(pts) * S


def check(g):
    F, V, uv = g.faces, g.verts, g.uv
    assert F.min() >= 0 and F.max() < len(V), g.name
    panels = np.unique(g.panel)
    assert len(panels) >= 2, f"{g.name}: {len(panels)} panels"
    # Metric UV: each UV edge is its rest 3-D edge in metres (within 20 %).
    for k in range(3):
        e3 = np.linalg.norm(V[F[:, k]] - V[F[:, (k + 1) % 3]], axis=1) / S
        e2 = np.linalg.norm(uv[:, k] - uv[:, (k + 1) % 3], axis=1)
        ratio = np.median(e2 / e3)
        assert 0.8 < ratio < 1.2, f"{g.name}: UV/3-D edge ratio {ratio}"
    # One island per panel: faces of a panel connected through shared UV corners.
    for p in panels:
        idx = np.nonzero(g.panel == p)[0]
        key = {}
        parent = list(range(len(idx)))
        def find(i):
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i
        for j, fi in enumerate(idx):
            for k in range(3):
                kk = (int(F[fi, k]), round(float(uv[fi, k, 0]), 5), round(float(uv[fi, k, 1]), 5))
                if kk in key:
                    parent[find(j)] = find(key[kk])
                else:
                    key[kk] = j
        roots = {find(j) for j in range(len(idx))}
        assert len(roots) == 1, f"{g.name}: panel {p} has {len(roots)} UV islands"
    # Faces wind counter-clockwise seen from outside: normals point away from the body axis.
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    c = V[F].mean(1)
    radial = c[:, :2] - np.array([0.0, -0.03 * S])
    if g.kind.startswith("pants"):   # legs: measure from each leg's axis below the crotch
        legs = c[:, 2] < 0.83 * S
        radial[legs, 0] = c[legs, 0] - np.sign(c[legs, 0]) * 0.1 * S
    outward = (n[:, :2] * radial).sum(1) > 0
    assert outward.mean() > 0.95, f"{g.name}: only {outward.mean():.2f} of faces point outwards"
    assert g.pin.max() == 1.0
    # generate/add_pins.py recovers the pins of older files from the rest shape (float32 there).
    pin, why = top_ring_pin(g.verts.astype(np.float32), g.faces)
    assert why is None and np.array_equal(pin, g.pin), f"{g.name}: top-ring pins differ ({why})"


def main():
    body = synthetic_body()
    prof = BodyProfile(body, centre=(0.0, -0.03 * S), arm_x=0.25 * S)
    kinds = 0
    for i, inner in enumerate(outfits.INNER_KINDS + outfits.EXTRA_INNER_KINDS):
        for j, outer in enumerate(outfits.OUTER_KINDS + outfits.EXTRA_OUTER_KINDS):
            rng = np.random.default_rng(10 * i + j)
            gs = outfits.build_outfit(prof, inner, outer, rng)
            for g in gs:
                check(g)
            # The outer layer starts outside the inner one: at matching heights its radius
            # around the torso axis is larger (ring by ring, compared on common heights).
            a, b = gs[0], gs[1]
            assert (a.kind == inner or a.kind.startswith("skirt_") and inner == "skirt") and b.kind == outer, (a.kind, b.kind)
            if not inner.startswith("pants"):
                cols = outfits.COLS
                ra = a.verts.reshape(-1, cols, 3)
                rb = b.verts.reshape(-1, cols, 3)
                rad = lambda r: np.hypot(r[..., 0], r[..., 1] + 0.03 * S)
                checked = 0
                zb = rb[:, 0, 2]           # descending heights of the outer rings
                for ring in ra:
                    z = ring[0, 2]
                    if not (zb[-1] <= z <= zb[0]):
                        continue
                    k = min(np.searchsorted(-zb, -z), len(zb) - 1)
                    k0 = max(k - 1, 0)
                    w = 0.0 if k == k0 else (zb[k0] - z) / (zb[k0] - zb[k])
                    r_out = (1 - w) * rad(rb[k0]) + w * rad(rb[k])
                    margin = r_out - rad(ring)
                    assert margin.min() > 0.5 * outfits.GAP * S, f"{inner}/{outer}: outer only {margin.min()} outside"
                    checked += 1
                assert checked > 0
            kinds += 1
    # A finer resolution (the recipe keys garment_spacing_m / ring_vertices) keeps the checks.
    for g in outfits.build_outfit(prof, "pants_tight", "coat_sleeveless", np.random.default_rng(1), 0.025, 64):
        check(g)
    # Long families reach lower than their short ones: hems below the knee (0.48 m).
    rng = np.random.default_rng(5)
    for inner in ("skirt_long", "dress_long"):
        g = outfits.build_outfit(prof, inner, "coat_long", rng)
        assert g[0].verts[:, 2].min() < 0.40 * S and g[1].verts[:, 2].min() < 0.36 * S, inner
    # Loose trousers stand farther off the legs than tight ones (same draw otherwise).
    tight = outfits.build_outfit(prof, "pants_tight", "jacket_sleeveless", np.random.default_rng(2))[0]
    loose = outfits.build_outfit(prof, "pants_loose", "jacket_sleeveless", np.random.default_rng(2))[0]
    spread = lambda g: np.ptp(g.verts[g.verts[:, 2] < 0.5 * S][:, 1])
    assert spread(loose) > spread(tight) + 0.03 * S, (spread(loose), spread(tight))
    check_stiffness_groups()
    n_kinds = len(outfits.INNER_KINDS + outfits.EXTRA_INNER_KINDS + outfits.OUTER_KINDS + outfits.EXTRA_OUTER_KINDS)
    print(f"ok: {kinds} outfits, {n_kinds} garment kinds")



def check_stiffness_groups():
    """What Blender simulates each layer with (base + w * |max - base| per vertex group) under
    both rules, for an outer layer stiffer and softer than the inner one."""
    for inner_t, outer_t in ((20.0, 80.0), (80.0, 20.0)):
        layers = [{"tension_stiffness": inner_t, "bending_stiffness": outer_t},
                  {"tension_stiffness": outer_t, "bending_stiffness": inner_t}]
        for rule in ("outer_max", "per_layer"):
            settings, groups = outfits.stiffness_groups(layers, rule)
            weights = dict(groups)
            for prop in ("tension", "bending"):
                group, base, top = settings[prop]
                simulated = [base + w * abs(top - base) for w in weights[group]]
                stored = [a[prop + "_stiffness"] for a in layers]
                if rule == "per_layer" or stored[1] >= stored[0]:
                    assert simulated == stored, (rule, prop, simulated, stored)
                else:  # the older rule: an outer value below the inner is mirrored about it
                    assert simulated == [stored[0], 2 * stored[0] - stored[1]], (rule, prop, simulated)
    try:
        outfits.stiffness_groups(layers, "outer")
        raise AssertionError("an unknown rule was accepted")
    except ValueError as e:
        assert "per_layer" in str(e)


if __name__ == "__main__":
    main()
