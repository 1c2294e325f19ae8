"""Outfits (inner + outer garment) and their sampled shape parameters (numpy only).

Heights are metres on the MakeHuman rest body (1.66 m, z up, feet at 0); everything
returned is in scene units (x10). The outer layer is always built at least `GAP`
outside the inner layer's radius at the same height and angle, so the two layers
start without interpenetration.
"""
import math

import numpy as np

from garments import SCENE_SCALE, ArmAxis, pants_garment, sleeved_garment, tube_garment, tube_rings, _rows

S = SCENE_SCALE
INNER_KINDS = ("pants_tight", "skirt", "dress_strapless")
OUTER_KINDS = ("coat_sleeveless", "jacket_sleeveless")
# Opt-in families (a scene's inner_kinds / outer_kinds): skirts and dresses to the calf or
# ankle, wide trousers, a coat to the calf (the large recipe); a top and a jacket with sleeves;
# a long skirt from the waist worn over the inner layer (an outer layer below the knee that is
# not a coat).
EXTRA_INNER_KINDS = ("skirt_long", "dress_long", "pants_loose", "top_sleeved")
EXTRA_OUTER_KINDS = ("coat_long", "jacket_sleeved", "overskirt_long")
TIGHT_INNER = ("pants_tight",)
GAP = 0.02          # metres between the inner layer and the outer one at rest
SPACING = 0.045     # metres between garment rows (about the ring edge length)
COLS = 40           # vertices per ring; divisible by 2, 4, 8 panels
Z_WAIST, Z_CROTCH, Z_HIP, Z_CHEST = 1.00, 0.84, 0.93, 1.22
# Sleeved garments: the neckline ring above the shoulder tops next to the neck (1.38-1.40 m),
# the armholes' lower edge 3 cm under the armpits (1.23 m on the rest body).
Z_NECK, Z_ARMPIT = 1.40, 1.20
# Left arm axis of the rest body (metres): shoulder joint, elbow, wrist. The centres of the
# arm's cross-sections lie within 1.3 cm of these lines; the right arm mirrors x.
ARM_JOINTS = ((0.17, -0.02, 1.30), (0.371, -0.039, 1.105), (0.448, -0.185, 1.015))
ELBOW_BEND = 0.10   # metres of arm either side of the elbow over which the sleeve turns
ARMHOLE_DEG = 27.0  # half-width of an armhole around the side (90 / 270 degrees)
ARMHOLE_TOP_DEG = 15.0  # its half-width on the neckline, over the shoulder top
YOKE_BELOW = 0.06   # metres of body under a ring above the armpits that the ring clears
SLEEVE_START = 0.06  # metres along the arm from the shoulder joint: the armholes end about here
# An outer layer's armholes reach lower and its sleeves start farther out: under the arm its
# sleeve and its side must both pass outside the inner layer's, which meet at the armpit.
Z_ARMPIT_OUTER, SLEEVE_START_OUTER = 1.10, 0.19


def _inner(profile, kind, rng, spacing, cols):
    """Returns (garment, offset_fn metres->scene units, z_top) of the inner layer."""
    if kind == "pants_tight":
        off = rng.uniform(0.02, 0.03)
        hem = rng.uniform(0.10, 0.30)
        g = pants_garment("pants", profile, Z_WAIST * S, Z_CROTCH * S, hem * S, off * S, spacing * S, cols)
        return g, (lambda z: off * S), Z_WAIST
    if kind == "pants_loose":
        off = rng.uniform(0.04, 0.07)
        hem = rng.uniform(0.06, 0.25)
        g = pants_garment("pants", profile, Z_WAIST * S, Z_CROTCH * S, hem * S, off * S, spacing * S, cols,
                          kind="pants_loose")
        return g, (lambda z: off * S), Z_WAIST
    if kind in ("skirt_long", "dress_long"):
        dress = kind == "dress_long"
        panels = 4 if dress else int(rng.choice([4, 8]))
        hem = rng.uniform(0.12, 0.38)
        base, flare = rng.uniform(0.012, 0.025), rng.uniform(0.12, 0.40)
        fn = lambda z: (base + flare * max(0.0, Z_HIP - z / S)) * S
        top = Z_CHEST if dress else Z_WAIST
        rings = tube_rings(profile, _rows(top * S, hem * S, spacing * S), fn, cols, Z_HIP * S)
        return tube_garment("dress" if dress else "skirt", kind, rings, panels), fn, top
    if kind == "skirt":
        panels = int(rng.choice([2, 4, 8]))
        hem = rng.uniform(0.42, 0.62)
        base, flare = rng.uniform(0.012, 0.02), rng.uniform(0.05, 0.35)
        fn = lambda z: (base + flare * max(0.0, Z_HIP - z / S)) * S
        rings = tube_rings(profile, _rows(Z_WAIST * S, hem * S, spacing * S), fn, cols, Z_HIP * S)
        return tube_garment("skirt", f"skirt_{panels}_panels", rings, panels), fn, Z_WAIST
    if kind == "dress_strapless":
        hem = rng.uniform(0.42, 0.62)
        base, flare = rng.uniform(0.012, 0.02), rng.uniform(0.05, 0.3)
        fn = lambda z: (base + flare * max(0.0, Z_HIP - z / S)) * S
        rings = tube_rings(profile, _rows(Z_CHEST * S, hem * S, spacing * S), fn, cols, Z_HIP * S)
        return tube_garment("dress", "dress_strapless", rings, 2), fn, Z_CHEST
    if kind == "top_sleeved":
        off, hem = rng.uniform(0.015, 0.025), rng.uniform(0.88, 1.02)
        sleeve, sleeve_off = rng.uniform(0.14, 0.44), rng.uniform(0.015, 0.03)
        fn = lambda z: off * S
        g = _sleeved("top", kind, profile, hem, fn, sleeve, lambda t: sleeve_off * S, spacing, cols, False)
        return g, fn, Z_NECK
    raise ValueError(f"outfits.py: unknown inner garment kind '{kind}' (use one of {INNER_KINDS + EXTRA_INNER_KINDS})")


def arm_axes(bend=ELBOW_BEND):
    """{+1: left arm, -1: right arm} centre lines of the rest body, in scene units."""
    left = ArmAxis(*(np.array(j) * S for j in ARM_JOINTS), bend * S)
    return {1: left, -1: left.mirrored()}


def sleeve_positions(length, spacing, start):
    """Arc lengths (metres from the shoulder joint) of a sleeve's rings after its armhole: every
    `spacing` from SLEEVE_START, the first at or after `start`, and the cuff at `length`. The
    grid does not depend on the layer, so an outer sleeve's rings lie in the inner's planes."""
    j0 = int(math.ceil((start - SLEEVE_START) / spacing - 1e-9))
    n = max(j0 + 1, int(round((length - SLEEVE_START) / spacing)))
    return np.array([SLEEVE_START + spacing * j for j in range(max(j0, 1), n)] + [length])


def _sleeved(name, kind, profile, hem, fn, sleeve_length, sleeve_fn, spacing, cols, outer):
    """A sleeved garment from the neckline to `hem` (metres). Its armholes reach from row 1
    (inner layer: a shoulder seam one row under the neckline) or from the neckline (outer
    layer: its sleeve caps pass above the inner's seams) down to Z_ARMPIT or Z_ARMPIT_OUTER.
    Every layer's rows lie on one grid from the neckline (the last one moves to the hem), so
    an outer layer's rings are at the inner's heights. The garment carries sleeve_length
    (metres) and sleeve_offset (arc length -> offset, scene units) for an outer layer."""
    bottom, start = (Z_ARMPIT_OUTER, SLEEVE_START_OUTER) if outer else (Z_ARMPIT, SLEEVE_START)
    step = (Z_NECK - Z_ARMPIT) / max(2, int(round((Z_NECK - Z_ARMPIT) / spacing)))
    k = int(round((Z_NECK - bottom) / step))
    n = max(k + 1, int(round((Z_NECK - hem) / step)))
    z_rows = np.append(Z_NECK - step * np.arange(n), hem) * S
    t = sleeve_positions(sleeve_length, spacing, start) * S
    hole = max(1, int(round(ARMHOLE_DEG / 360.0 * cols)))
    g = sleeved_garment(name, kind, profile, z_rows, (0 if outer else 1, k), fn, Z_HIP * S, cols, arm_axes(), t,
                        sleeve_fn, hole, ARMHOLE_TOP_DEG, YOKE_BELOW * S, spacing * S)
    g.sleeve_length = sleeve_length
    g.sleeve_offset = sleeve_fn
    return g


def _outer(profile, kind, rng, inner_fn, inner_top, spacing, cols, inner_sleeve=None):
    """Outer layer: looser than the inner one by GAP plus a sampled ease, longer for coats.
    inner_sleeve: the inner layer's sleeve offset (scene units of arc length -> scene units),
    or None when it has no sleeves."""
    ease, flare = rng.uniform(0.0, 0.02), rng.uniform(0.05, 0.3)
    # Over sleeves a sleeveless outer layer starts under them (its top ring would cut them).
    top = Z_CHEST + 0.02 if inner_sleeve is None else Z_ARMPIT_OUTER

    def fn(z):
        zm = z / S
        inner = inner_fn(z) if zm <= inner_top + 1e-6 else 0.012 * S
        return inner + (GAP + ease + flare * max(0.0, Z_HIP - zm)) * S

    if kind == "jacket_sleeved":
        hem, sleeve, sleeve_ease = rng.uniform(0.72, 0.88), rng.uniform(0.30, 0.44), rng.uniform(0.0, 0.02)
        under = inner_sleeve if inner_sleeve is not None else (lambda t: 0.012 * S)
        return _sleeved("jacket", kind, profile, hem, fn, sleeve,
                        lambda t: under(t) + (GAP + sleeve_ease) * S, spacing, cols, True)
    if kind == "coat_sleeveless":
        hem, panels = rng.uniform(0.40, 0.60), 4
    elif kind == "jacket_sleeveless":
        hem, panels = rng.uniform(0.76, 0.88), int(rng.choice([2, 4]))
    elif kind == "coat_long":
        hem, panels = rng.uniform(0.15, 0.35), 4
    elif kind == "overskirt_long":
        hem, panels, top = rng.uniform(0.15, 0.35), int(rng.choice([4, 8])), Z_WAIST
    else:
        raise ValueError(f"outfits.py: unknown outer garment kind '{kind}' (use one of {OUTER_KINDS + EXTRA_OUTER_KINDS})")
    rings = tube_rings(profile, _rows(top * S, hem * S, spacing * S), fn, cols, Z_HIP * S)
    name = {"coat_sleeveless": "coat", "coat_long": "coat", "overskirt_long": "skirt"}.get(kind, "jacket")
    return tube_garment(name, kind, rings, panels)


def build_outfit(profile, inner_kind, outer_kind, rng, spacing=SPACING, cols=COLS):
    """[inner, outer] Garments around the rest body described by `profile`.
    spacing: metres between rows; cols: vertices per ring (a multiple of 8: 2/4/8 panels
    and the trousers' four quarter panels). Finer garments cost proportionally more."""
    if cols % 8 != 0:
        raise ValueError(f"outfits.py: ring vertex count {cols} must be a multiple of 8")
    inner, inner_fn, inner_top = _inner(profile, inner_kind, rng, spacing, cols)
    outer = _outer(profile, outer_kind, rng, inner_fn, inner_top, spacing, cols, getattr(inner, "sleeve_offset", None))
    if outer.name == inner.name:
        outer.name += "_outer"
    return [inner, outer]


def sample_attributes(rng, ranges):
    """D-LAYERS cloth attributes per layer. Blender has one mass and one self-friction per
    cloth object, and the two layers are one object (so that self-collision keeps them
    apart), so mass and self-friction are shared by both layers; tension and bending
    differ per layer (vertex-group scaled stiffness)."""
    u = lambda key: float(rng.uniform(*ranges[key]))
    shared = {"mass": u("mass"), "self_friction": u("self_friction")}
    layers = [{"tension_stiffness": u("tension_stiffness"), "bending_stiffness": u("bending_stiffness"),
               **shared} for _ in range(2)]
    return layers, u("body_friction")


def stiffness_groups(layer_attrs, rule):
    """How the layers' tension and bending reach Blender's one cloth object, whose setting per
    vertex is base + w * |max - base| (w the vertex's weight in the setting's vertex group).
    Returns {"tension": (group, base, max), "bending": (group, base, max)} and the groups as
    [(name, weight per layer)], in creation order.
      "outer_max": base = inner, max = outer, group 'outer' (weight 1 on the outer layer) for
                   both; an outer value below the inner one is simulated as 2*inner - outer.
      "per_layer": base = the smaller value, max = the larger, each property with its own group
                   weighting the layer with the larger value: every layer gets its stored value."""
    inner, outer = layer_attrs[0], layer_attrs[-1]
    n = len(layer_attrs)
    if rule == "outer_max":
        settings = {p: ("outer", inner[p + "_stiffness"], outer[p + "_stiffness"]) for p in ("tension", "bending")}
        return settings, [("outer", [float(i == n - 1) for i in range(n)])]
    if rule != "per_layer":
        raise ValueError(f"stiffness_groups must be 'outer_max' or 'per_layer', not {rule!r}")
    settings, groups = {}, []
    for p in ("tension", "bending"):
        values = [a[p + "_stiffness"] for a in layer_attrs]
        lo, hi = min(values), max(values)
        if any(v not in (lo, hi) for v in values):
            raise ValueError(f"per_layer stiffness groups hold two values per property, the layers have {values}")
        name = "stiff_" + p
        settings[p] = (name, lo, hi)
        groups.append((name, [float(v == hi and hi > lo) for v in values]))
    return settings, groups
