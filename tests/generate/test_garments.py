#!/usr/bin/python3
"""Checks the garment templates without Blender, on a synthetic rest body (ellipsoid torso,
two cylinder legs): panels, metric UVs, outward faces, the outer layer outside the inner.
The sleeved kinds are checked on a body of capsules with arms in the rest pose (check_sleeves)."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../generate"))
import outfits  # noqa: E402
from garments import SCENE_SCALE, BodyProfile, top_ring_pin  # noqa: E402

S = SCENE_SCALE
SLEEVED = ("top_sleeved", "jacket_sleeved")


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
    if hasattr(g, "sleeve_length"):  # sleeves (panels 2-5): away from the arm's centre line
        sleeve = g.panel >= 2
        arms = outfits.arm_axes()
        from_arm = np.array([p - _nearest_on_axis(arms[np.sign(p[0])], p, 111)[0] for p in c[sleeve]])
        outward[sleeve] = (n[sleeve] * from_arm).sum(1) > 0
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
            if inner in SLEEVED or outer in SLEEVED:
                continue   # this body has no arms: check_sleeves
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
    # The long overskirt hangs from the waist to below the knee, over every unsleeved inner kind.
    for i, inner in enumerate(("pants_tight", "pants_loose", "skirt", "dress_strapless")):
        g = outfits.build_outfit(prof, inner, "overskirt_long", np.random.default_rng(30 + i))[1]
        z = g.verts[:, 2] / S
        assert g.name.startswith("skirt") and abs(z.max() - outfits.Z_WAIST) < 1e-6, (inner, z.max())
        assert z.min() < 0.36, (inner, z.min())
    # Loose trousers stand farther off the legs than tight ones (same draw otherwise).
    tight = outfits.build_outfit(prof, "pants_tight", "jacket_sleeveless", np.random.default_rng(2))[0]
    loose = outfits.build_outfit(prof, "pants_loose", "jacket_sleeveless", np.random.default_rng(2))[0]
    spread = lambda g: np.ptp(g.verts[g.verts[:, 2] < 0.5 * S][:, 1])
    assert spread(loose) > spread(tight) + 0.03 * S, (spread(loose), spread(tight))
    check_stiffness_groups()
    check_sleeves()
    n_kinds = len(outfits.INNER_KINDS + outfits.EXTRA_INNER_KINDS + outfits.OUTER_KINDS + outfits.EXTRA_OUTER_KINDS)
    print(f"ok: {kinds} outfits, {n_kinds} garment kinds")


def _capsules():
    """A rest body of capsules (segment a-b, radius; metres): torso, shoulders, neck and head,
    the arms along outfits.ARM_JOINTS (hanging about 45 degrees from vertical), hands, hips, legs."""
    sh, el, wr = (np.array(j) for j in outfits.ARM_JOINTS)
    hand = wr + 0.06 * (wr - el) / np.linalg.norm(wr - el)
    parts = [((0, -0.03, 0.95), (0, -0.03, 1.26), 0.13), ((-0.17, -0.02, 1.30), (0.17, -0.02, 1.30), 0.06),
             ((0, -0.02, 1.30), (0, -0.02, 1.62), 0.055), ((0, -0.02, 1.52), (0, -0.03, 1.60), 0.09),
             ((-0.08, -0.03, 0.92), (0.08, -0.03, 0.92), 0.09)]
    for x in (1, -1):
        f = np.array([x, 1, 1])
        parts += [(sh * f, el * f, 0.05), (el * f, wr * f, 0.04), (wr * f, hand * f, 0.03),
                  ((0.1 * x, -0.03, 0.9), (0.12 * x, -0.03, 0.05), 0.07)]
    return [(np.array(a, float), np.array(b, float), r) for a, b, r in parts]


def body_sdf(p, parts):
    """Signed distance (metres) of points p (N, 3) in metres to the union of capsules."""
    d = np.full(len(p), np.inf)
    for a, b, r in parts:
        ab = b - a
        t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(p - (a + t[:, None] * ab), axis=1) - r)
    return d


def capsule_body(parts, step=0.01):
    """Points (scene units) on the surface of the union of capsules, about `step` metres apart."""
    pts = []
    for a, b, r in parts:
        ab = b - a
        length = np.linalg.norm(ab)
        u = ab / length
        e1 = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        ang = np.linspace(0, 2 * np.pi, max(12, int(2 * np.pi * r / step)), endpoint=False)
        ring = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2
        for t in np.linspace(0, length, max(2, int(length / step) + 1)):
            pts.append(a + t * u + r * ring)
        for k in range(1, int(np.pi / 2 * r / step) + 1):   # hemispherical caps
            phi = k * step / r
            for end, sgn in ((a, -1), (b, 1)):
                pts.append(end + r * (np.cos(phi) * ring + sgn * np.sin(phi) * u))
    pts = np.concatenate(pts)
    return pts[body_sdf(pts, parts) > -1e-6] * S


def _nearest_on_axis(axis, p, n=551):
    """Nearest point (scene units) to p on an outfits.arm_axes() centre line, shoulder to hand,
    and its arc length in metres."""
    ts = np.linspace(0.0, 0.55 * S, n)
    pts = np.array([axis.point(t) for t in ts])
    k = np.argmin(np.linalg.norm(pts - p, axis=1))
    return pts[k], ts[k] / S


def _edges(F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def crossings(V, F, chunk=128):
    """Number of (edge, face) pairs of a mesh where an edge passes through a face it does not
    touch: 0 for a mesh without self-intersections."""
    E, _ = _edges(F)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    flo, fhi = np.minimum(np.minimum(A, B), C), np.maximum(np.maximum(A, B), C)
    P, Q = V[E[:, 0]], V[E[:, 1]]
    elo, ehi = np.minimum(P, Q), np.maximum(P, Q)
    hits = 0
    for s0 in range(0, len(E), chunk):
        ei, fi = np.nonzero(np.all((elo[s0:s0 + chunk, None] <= fhi[None]) & (ehi[s0:s0 + chunk, None] >= flo[None]), 2))
        ei += s0
        apart = ~((F[fi] == E[ei, :1]).any(1) | (F[fi] == E[ei, 1:]).any(1))
        ei, fi = ei[apart], fi[apart]
        o, d = P[ei], Q[ei] - P[ei]
        e1, e2 = B[fi] - A[fi], C[fi] - A[fi]
        h = np.cross(d, e2)
        a = (e1 * h).sum(1)
        ok = np.abs(a) > 1e-12
        f = 1.0 / np.where(ok, a, 1.0)
        sv = o - A[fi]
        u = f * (sv * h).sum(1)
        q = np.cross(sv, e1)
        v, t = f * (d * q).sum(1), f * (e2 * q).sum(1)
        hits += int((ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)).sum())
    return hits


def signed_distance(p, V, F, chunk=64):
    """Distance (scene units) from points p to the nearest point of the triangles (V, F), positive
    on the side the nearest face's normal points to."""
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    nrm = np.cross(B - A, C - A)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    out = np.empty(len(p))
    for s0 in range(0, len(p), chunk):
        x = p[s0:s0 + chunk, None, :]
        # Closest point on each triangle: inside the face, else on its nearest edge.
        w = x - A[None]
        n_ = nrm[None]
        proj = x - (w * n_).sum(-1, keepdims=True) * n_
        inside = np.ones(proj.shape[:2], bool)
        for a_, b_ in ((A, B), (B, C), (C, A)):
            inside &= (np.cross(b_ - a_, proj - a_[None]) * n_).sum(-1) >= 0
        best = np.where(inside[..., None], proj, np.inf)
        dist = np.where(inside, np.linalg.norm(x - proj, axis=-1), np.inf)
        for a_, b_ in ((A, B), (B, C), (C, A)):
            ab = b_ - a_
            t = np.clip(((x - a_[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0, 1)
            q = a_[None] + t[..., None] * ab[None]
            dq = np.linalg.norm(x - q, axis=-1)
            better = dq < dist
            dist, best = np.where(better, dq, dist), np.where(better[..., None], q, best)
        j = np.argmin(dist, axis=1)
        r = np.arange(len(j))
        side = np.sign(((x[:, 0] - best[r, j]) * nrm[j]).sum(-1))
        out[s0:s0 + chunk] = side * dist[r, j]
    return out


def cuff_positions(g):
    """Arc length (metres from the shoulder joint) of each cuff's centre along its arm's axis:
    the cuffs are the boundary loops away from the neckline and the hem."""
    E, count = _edges(g.faces)
    boundary = E[count == 1]
    sleeve_v = np.setdiff1d(np.unique(g.faces[g.panel >= 2]), np.nonzero(g.pin)[0])  # not the neckline
    cuff = boundary[np.isin(boundary, sleeve_v).all(1)]
    arms = outfits.arm_axes()
    out = {}
    for side in (1, -1):
        ids = np.unique(cuff[np.sign(g.verts[cuff[:, 0], 0]) == side])
        out[side] = _nearest_on_axis(arms[side], g.verts[ids].mean(0))[1]
    return out


def check_sleeved_geometry(g, parts, offset):
    """One sleeved garment: a manifold surface (every edge in one or two faces) of genus 0 with
    four boundary loops (neckline, hem, two cuffs), no self-intersection, rest edges of about
    outfits.SPACING (0.2-3 x, as the other kinds have on the real body: 0.26-3.0), every vertex at least 0.6 x `offset` (metres) outside the body, the pins
    on the neckline and nothing above it, the cuffs where the drawn sleeve length puts them."""
    check(g)
    E, count = _edges(g.faces)
    assert count.max() <= 2, f"{g.kind}: an edge in {count.max()} faces"
    assert len(np.unique(g.faces)) == len(g.verts), f"{g.kind}: unused vertices"
    boundary = E[count == 1]
    assert np.bincount(boundary.ravel(), minlength=len(g.verts))[np.unique(boundary)].max() == 2, g.kind
    euler = len(g.verts) - len(E) + len(g.faces)
    assert euler == -2, f"{g.kind}: Euler characteristic {euler}, a sphere with four holes has -2"
    assert crossings(g.verts, g.faces) == 0, f"{g.kind}: the rest shape intersects itself"
    length = np.linalg.norm(g.verts[E[:, 0]] - g.verts[E[:, 1]], axis=1) / S / outfits.SPACING
    assert 0.2 < length.min() and length.max() < 3.0 and 0.8 < np.median(length) < 1.2, \
        f"{g.kind}: rest edges {length.min():.2f}-{length.max():.2f} x SPACING (median {np.median(length):.2f})"
    clearance = body_sdf(g.verts / S, parts)
    assert clearance.min() > 0.6 * offset, f"{g.kind}: a vertex {clearance.min() * 100:.2f} cm off the body"
    cuffs = cuff_positions(g)
    for side, t in cuffs.items():
        assert abs(t - g.sleeve_length) < 0.02, f"{g.kind}: cuff at {t:.3f} m, drawn sleeve {g.sleeve_length:.3f} m"
    return clearance.min()


def check_layers(inner, outer):
    """The outer layer starts outside the inner one: the two surfaces do not cross, and every
    outer vertex within 5 cm of the inner surface is at least GAP / 4 on its outer side."""
    V = np.concatenate([inner.verts, outer.verts])
    F = np.concatenate([inner.faces, outer.faces + len(inner.verts)])
    assert crossings(V, F) == crossings(inner.verts, inner.faces) + crossings(outer.verts, outer.faces), \
        f"{inner.kind}/{outer.kind}: the layers cross"
    d = signed_distance(outer.verts, inner.verts, inner.faces) / S
    near = np.abs(d) < 0.05
    assert d[near].min() > 0.25 * outfits.GAP, f"{inner.kind}/{outer.kind}: outer only {d[near].min() * 100:.2f} cm out"
    return d[near].min()


def check_sleeves():
    """top_sleeved and jacket_sleeved on the capsule body: alone, worn together, and each with
    the sleeveless kinds of the other layer; the sleeve length follows its drawn parameter."""
    parts = _capsules()
    prof = BodyProfile(capsule_body(parts), centre=(0.0, -0.03 * S), arm_x=0.35 * S)
    lengths = []
    for seed in range(3):
        inner, outer = outfits.build_outfit(prof, "top_sleeved", "jacket_sleeved", np.random.default_rng(seed))
        check_sleeved_geometry(inner, parts, 0.015)
        check_layers(inner, outer)
        check_sleeved_geometry(outer, parts, 0.015 + outfits.GAP)
        lengths.append((inner.sleeve_length, cuff_positions(inner)[1]))
    for seed, other in enumerate(("pants_tight", "dress_strapless")):
        inner, outer = outfits.build_outfit(prof, other, "jacket_sleeved", np.random.default_rng(seed))
        check_layers(inner, outer)
        check_sleeved_geometry(outer, parts, 0.012 + outfits.GAP)
    inner, outer = outfits.build_outfit(prof, "top_sleeved", "coat_sleeveless", np.random.default_rng(3))
    check(outer)
    check_layers(inner, outer)
    # Short to long: a longer drawn sleeve puts the cuff farther down the arm.
    lengths.sort()
    assert all(b[1] > a[1] for a, b in zip(lengths, lengths[1:])), lengths
    for length in (0.14, 0.44):
        t = outfits.sleeve_positions(length, outfits.SPACING, outfits.SLEEVE_START)
        assert abs(t[-1] - length) < 1e-12 and np.all(np.diff(t) > 0.4 * outfits.SPACING), t


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
