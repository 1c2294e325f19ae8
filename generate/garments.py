"""Garment templates sewn from panels around the rest-pose body (numpy only, no bpy).

Every garment is built as rings of vertices around the body at a sequence of heights;
the panels are angular sectors of the rings, joined at their seam columns (the
welded result of sewing). Each panel's UV island is its flattening in metres: u is
the arc length along the ring from the panel's first seam, v the distance down the
column from the garment's top. These strips are near-developable, so one metre of
UV is about one metre of rest cloth on every panel and garment (a common metric
UV scale, which LayersNet's 0.04 patch size assumes).

Units: positions in scene units (SCENE_SCALE per metre, the body is z-up and faces
-y); UV in metres. Faces wind counter-clockwise seen from outside the body.
"""
import math

import numpy as np

SCENE_SCALE = 10.0  # scene units per metre (D-LAYERS scales the world x10)


class Garment:
    """verts: (N, 3) scene units; faces: (F, 3); uv: (F, 3, 2) metres; panel: (F,);
    pin: (N,) weight 0..1 of the cloth pin group (waistband / top edge)."""

    def __init__(self, name, kind, verts, faces, uv, panel, pin):
        self.name, self.kind = name, kind
        self.verts = np.asarray(verts, np.float64)
        self.faces = np.asarray(faces, np.int64)
        self.uv = np.asarray(uv, np.float64)
        self.panel = np.asarray(panel, np.int64)
        self.pin = np.asarray(pin, np.float64)


class BodyProfile:
    """Horizontal cross-sections of the rest-pose body, measured per angle bin.

    body: (B, 3) rest vertices in scene units. centre: torso axis (x, y) in scene units.
    arm_x: |x| beyond which vertices above the crotch belong to the arms (scene units).
    """

    def __init__(self, body, centre, arm_x, bins=64, slab=0.15):
        self.body = body
        self.centre = np.asarray(centre, np.float64)
        self.arm_x = arm_x
        self.bins = bins
        self.slab = slab

    def hull(self, z, max_x, below=0.0):
        """(bins,) largest radius around the torso axis of body points near height z with
        |x| < max_x, per angle bin (angle 0 = front, -y; increasing towards +x). `below`
        (scene units) adds the points that far under the slab: a ring over a nearly flat
        surface (the shoulder tops) then clears it upwards as well as sideways."""
        if below:
            h = self.body[:, 2] - z
            pts = self.body[(h > -self.slab - below) & (h < self.slab)]
        else:
            pts = self.body[np.abs(self.body[:, 2] - z) < self.slab]
        pts = pts[np.abs(pts[:, 0]) < max_x]
        r = np.zeros(self.bins)
        if len(pts) == 0:
            return r
        d = pts[:, :2] - self.centre
        ang = np.arctan2(d[:, 0], -d[:, 1]) % (2 * math.pi)
        idx = (ang / (2 * math.pi) * self.bins).astype(int) % self.bins
        np.maximum.at(r, idx, np.hypot(d[:, 0], d[:, 1]))
        return _fill_and_smooth(r)

    def leg_hull(self, z, side, centre):
        """(bins,) radius around a leg axis `centre` (x, y) of the leg on `side` (+1 left, -1 right)."""
        pts = self.body[np.abs(self.body[:, 2] - z) < self.slab]
        pts = pts[(pts[:, 0] * side > 0) & (np.abs(pts[:, 0]) < self.arm_x)]
        r = np.zeros(self.bins)
        d = pts[:, :2] - centre
        ang = np.arctan2(d[:, 0], -d[:, 1]) % (2 * math.pi)
        idx = (ang / (2 * math.pi) * self.bins).astype(int) % self.bins
        np.maximum.at(r, idx, np.hypot(d[:, 0], d[:, 1]))
        return _fill_and_smooth(r)

    def section(self, centre, normal, e1, e2, slab, max_r, min_side_x):
        """(bins,) largest radius around `centre` (scene units) in the plane with unit `normal`,
        of body points within `slab` of the plane and `max_r` of the centre whose x, times the
        sign of the centre's x, is at least `min_side_x` (the arm, not the torso beside it).
        Angle 0 along the in-plane unit vector e1, increasing towards e2."""
        d = self.body - centre
        side = 1.0 if centre[0] >= 0 else -1.0
        m = (np.abs(d @ normal) < slab) & (self.body[:, 0] * side >= min_side_x)
        a, b = d[m] @ e1, d[m] @ e2
        rad = np.hypot(a, b)
        near = rad < max_r
        r = np.zeros(self.bins)
        ang = np.arctan2(b[near], a[near]) % (2 * math.pi)
        idx = (ang / (2 * math.pi) * self.bins).astype(int) % self.bins
        np.maximum.at(r, idx, rad[near])
        return _fill_and_smooth(r)

    def leg_centre(self, z, side):
        pts = self.body[np.abs(self.body[:, 2] - z) < self.slab]
        pts = pts[(pts[:, 0] * side > 0.02 * SCENE_SCALE) & (np.abs(pts[:, 0]) < self.arm_x)]
        lo, hi = pts.min(0), pts.max(0)
        return 0.5 * (lo[:2] + hi[:2])


def _fill_and_smooth(r):
    """Fill empty angle bins by circular interpolation, then take a running max over
    3 bins so thin gaps between sampled vertices do not dent the garment."""
    n = len(r)
    full = np.nonzero(r > 0)[0]
    if len(full) == 0:
        return r
    xs = np.concatenate([full - n, full, full + n])
    ys = np.tile(r[full], 3)
    out = np.interp(np.arange(n), xs, ys)
    return np.maximum(np.maximum(out, np.roll(out, 1)), np.roll(out, -1))


def _sample(radius_bins, angles):
    """Radius at arbitrary angles (radians, 0 = front) by linear interpolation of bins."""
    n = len(radius_bins)
    t = (angles % (2 * math.pi)) / (2 * math.pi) * n - 0.5
    i0 = np.floor(t).astype(int)
    w = t - i0
    return (1 - w) * radius_bins[i0 % n] + w * radius_bins[(i0 + 1) % n]


def _ring_point(centre, angle, radius, z):
    return np.stack([centre[0] + radius * np.sin(angle), centre[1] - radius * np.cos(angle),
                     np.full_like(angle, z)], axis=-1)


def _grid_faces(rows, cols, cyclic):
    """Triangles of a (rows, cols) vertex grid whose rows go down the body and columns
    around it (angle increasing towards +x, i.e. counter-clockwise seen from above), with
    alternating diagonals. Returns (F, 3) grid indices r*cols+c and (F,) column of each face."""
    faces, fcol = [], []
    ncol = cols if cyclic else cols - 1
    for r in range(rows - 1):
        for c in range(ncol):
            c1 = (c + 1) % cols
            a, b = r * cols + c, r * cols + c1
            d, e = (r + 1) * cols + c, (r + 1) * cols + c1
            # Outward normal: ring order runs counter-clockwise seen from above and rows go
            # down, so (a, d, e) / (a, e, b) face outwards.
            if (r + c) % 2 == 0:
                faces += [(a, d, e), (a, e, b)]
            else:
                faces += [(a, d, b), (b, d, e)]
            fcol += [c, c]
    return np.array(faces, np.int64), np.array(fcol, np.int64)


def _arc(row_pos):
    """Cumulative arc length (metres) along a cyclic row: (cols + 1,), last = perimeter."""
    p = row_pos / SCENE_SCALE
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


class _Builder:
    """Accumulates ring-grid blocks into one garment mesh with panel UVs."""

    def __init__(self):
        self.pos = []        # list of (3,) scene units
        self.faces, self.face_panel, self.uv = [], [], []

    def add_vertices(self, pts):
        start = len(self.pos)
        self.pos.extend(list(pts))
        return np.arange(start, start + len(pts))

    def add_block(self, ids, v0, panel_of_col, anchor_of_panel, keep=None):
        """ids: (rows, cols) vertex ids of a cyclic grid (rows go down, columns run
        counter-clockwise seen from above). v0: (cols,) v (metres) of the top row.
        panel_of_col: (cols,) panel id of the faces right of each column.
        anchor_of_panel: dict panel -> column whose u is 0 (the panel's reference seam).
        keep: optional (rows - 1, cols) bool, False where the cell right of a column and
        below a row has no faces (a hole such as an armhole)."""
        rows, cols = ids.shape
        pos = np.array(self.pos)[ids]                              # (rows, cols, 3)
        arcs = np.stack([_arc(pos[r]) for r in range(rows)])       # (rows, cols+1)
        dv = np.linalg.norm(np.diff(pos, axis=0), axis=2) / SCENE_SCALE
        v = v0[None, :] + np.concatenate([np.zeros((1, cols)), np.cumsum(dv, axis=0)], axis=0)
        tri, fcol = _grid_faces(rows, cols, cyclic=True)
        if keep is not None:
            cell = keep[tri[:, 0] // cols, fcol]   # a face's first corner is on its cell's upper row
            tri, fcol = tri[cell], fcol[cell]
        for t, c in zip(tri, fcol):
            p = int(panel_of_col[c])
            a = anchor_of_panel[p]
            corner_uv = []
            for vid in t:
                r, cc = divmod(int(vid), cols)
                # Unwrap the corner column next to the face column, then measure from the anchor.
                cu = cc if cc >= c else cc + cols
                d = (cu - a) % cols
                if d > cols // 2:
                    d -= cols
                j = a + d
                s = arcs[r, j % cols] + (arcs[r, cols] if j >= cols else 0.0) - \
                    (arcs[r, cols] if j < 0 else 0.0)
                u = s - arcs[r, a]
                corner_uv.append((u, -v[r, cc]))
            self.faces.append([int(ids.flat[i]) for i in t])
            self.face_panel.append(p)
            self.uv.append(corner_uv)

    def finish(self, name, kind, pin):
        uv = np.array(self.uv)
        panel = np.array(self.face_panel)
        offset = 0.0
        for p in np.unique(panel):
            m = panel == p
            uv[m, :, 0] += offset - uv[m, :, 0].min()
            offset = uv[m, :, 0].max() + 0.05
        return Garment(name, kind, np.array(self.pos), np.array(self.faces), uv, panel, pin)


def _rows(z_top, z_bottom, spacing):
    n = max(2, int(round((z_top - z_bottom) / spacing)) + 1)
    return np.linspace(z_top, z_bottom, n)


def _max_x(z):
    """|x| (scene units) that separates the torso/legs from the arms and hands in the rest pose."""
    if z > 0.97 * SCENE_SCALE:
        return 0.175 * SCENE_SCALE
    return 0.25 * SCENE_SCALE if z > 0.88 * SCENE_SCALE else 0.35 * SCENE_SCALE


def tube_rings(profile, z_rows, offset_fn, cols, hang_below):
    """(R, cols, 3) rings around the torso axis: radius = body hull + offset_fn(z).
    Below `hang_below` the hull never shrinks going down (cloth hangs from the hips)."""
    ang = np.arange(cols) / cols * 2 * math.pi
    rings, prev = [], None
    for z in z_rows:
        hull = profile.hull(z, _max_x(z))
        if prev is not None and z < hang_below:
            hull = np.maximum(hull, prev)
        prev = hull
        r = _sample(hull, ang) + offset_fn(z)
        rings.append(_ring_point(profile.centre, ang, r, z))
    return np.array(rings)


def tube_garment(name, kind, rings, panels):
    """Closed tube from rings (R, M, 3); `panels` equal angular panels, anchored at their
    first column; the top row is the pinned waistband / top edge."""
    rows, cols, _ = rings.shape
    assert cols % panels == 0, "ring vertex count must be divisible by the panel count"
    b = _Builder()
    ids = b.add_vertices(rings.reshape(-1, 3)).reshape(rows, cols)
    per = cols // panels
    b.add_block(ids, np.zeros(cols), np.arange(cols) // per, {p: p * per for p in range(panels)})
    pin = np.zeros(rows * cols)
    pin[:cols] = 1.0
    return b.finish(name, kind, pin)


def top_ring_pin(rest, faces, up=2, tol=1e-3):
    """The pin weights of a garment of this module, recovered from its rest shape: every
    kind pins exactly its top ring (the tubes' first row, the trousers' waist). Weight 1
    within `tol` scene units of the highest rest coordinate along axis `up`, else 0.
    Returns (pin, None), or (None, why) when those vertices are not one closed boundary
    loop of the mesh (then the garment was not built here)."""
    rest, faces = np.asarray(rest, np.float64), np.asarray(faces, np.int64)
    h = rest[:, up]
    top = np.nonzero(h >= h.max() - tol)[0]
    if len(top) < 3:
        return None, f"{len(top)} vertices at the top (within {tol:g}), a ring needs at least 3"
    # Boundary edges belong to one face; the top ring must be one whole loop of them.
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    nbr = {}
    for a, b in uniq[count == 1]:
        nbr.setdefault(int(a), []).append(int(b))
        nbr.setdefault(int(b), []).append(int(a))
    start = int(top[np.argmax(h[top])])
    loop, prev, v = [start], -1, start
    while True:
        if len(nbr.get(v, ())) != 2:
            return None, f"top vertex {v} is not on a simple boundary loop"
        nxt = nbr[v][0] if nbr[v][0] != prev else nbr[v][1]
        if nxt == start:
            break
        loop.append(nxt)
        prev, v = v, nxt
        if len(loop) > len(rest):
            return None, "boundary walk does not close"
    if set(loop) != set(top.tolist()):
        return None, (f"{len(top)} vertices at the top, but the top boundary loop has "
                      f"{len(loop)} vertices")
    pin = np.zeros(len(rest))
    pin[top] = 1.0
    return pin, None


def pants_garment(name, profile, z_waist, z_crotch, z_hem, offset, spacing, cols=40, kind="pants_tight"):
    """Trousers: a hip tube from the waist to the crotch that splits into two leg tubes.
    The crotch seam is a chain of vertices from front centre to back centre shared by
    both legs. Panels: 0 left-front, 1 left-back, 2 right-back, 3 right-front."""
    H = cols // 2
    hip = tube_rings(profile, _rows(z_waist, z_crotch, spacing), lambda z: offset, cols, -1e9)
    b = _Builder()
    hip_ids = b.add_vertices(hip.reshape(-1, 3)).reshape(len(hip), cols)
    q = H // 2
    panel_hip = np.array([0] * q + [1] * q + [2] * q + [3] * q)
    b.add_block(hip_ids, np.zeros(cols), panel_hip, {0: 0, 1: H, 2: H, 3: 0})
    crotch = hip[-1]
    front, back = crotch[0], crotch[H]
    depth = np.linalg.norm(back - front) / SCENE_SCALE
    K = max(3, int(round(depth / (spacing / SCENE_SCALE))) - 1)
    t = np.arange(1, K + 1) / (K + 1)
    chain = front[None, :] * (1 - t[:, None]) + back[None, :] * t[:, None]
    chain[:, 2] -= 0.02 * SCENE_SCALE * np.sin(math.pi * t)
    chain_ids = b.add_vertices(chain)
    hv = lambda c: 0.0 + np.linalg.norm(np.diff(hip[:, c], axis=0), axis=1).sum() / SCENE_SCALE
    for side in (1, -1):
        if side == 1:   # left leg: front centre -> left side -> back centre -> chain back to front
            top_ids = np.concatenate([hip_ids[-1, 0:H + 1], chain_ids[::-1]])
            panels = [0] * q + [1] * q + [1] * ((K + 1) // 2) + [0] * (K + 1 - (K + 1) // 2)
            anchors = {0: 0, 1: H}
        else:           # right leg: back centre -> right side -> front centre -> chain to back
            top_ids = np.concatenate([hip_ids[-1, H:], hip_ids[-1, :1], chain_ids])
            panels = [2] * q + [3] * q + [3] * ((K + 1) // 2) + [2] * (K + 1 - (K + 1) // 2)
            anchors = {2: 0, 3: H}
        L = len(top_ids)
        top = np.array(b.pos)[top_ids]
        zc = profile.leg_centre(z_crotch - 0.05 * SCENE_SCALE, side)
        ang = np.unwrap(np.arctan2(top[:, 0] - zc[0], -(top[:, 1] - zc[1])))
        if ang[-1] < ang[0]:
            ang = 2 * ang[0] - ang   # keep counter-clockwise order increasing
        # The crotch ring's vertices bunch up in angle; going down the leg they spread evenly,
        # so that hem edges are not a few millimetres long (noisy strain, stiff solver).
        even = ang[0] + 2 * math.pi * np.arange(L) / L
        ring_ids = [top_ids]
        z_leg = _rows(z_crotch, z_hem, spacing)[1:]
        for j, z in enumerate(z_leg):
            c = profile.leg_centre(z, side)
            a = ang + min(1.0, (j + 1) / 4.0) * (even - ang)
            r = _sample(profile.leg_hull(z, side, c), a) + offset
            leg_pt = _ring_point(c, a, r, z)
            # Where the thighs touch, the leg hull plus offset would cross the midplane into
            # the other thigh: keep each trouser leg on its own side of it.
            leg_pt[:, 0] = side * np.maximum(side * leg_pt[:, 0], 0.003 * SCENE_SCALE)
            w = min(1.0, (j + 1) / 3.0)   # blend the crotch D-shape into the leg tube
            pts = (1 - w) * np.concatenate([top[:, :2], np.full((L, 1), z)], axis=1) + w * leg_pt
            ring_ids.append(b.add_vertices(pts))
        v0 = np.array([hv(c) for c in range(cols)])
        hip_col = {int(vid): c for c, vid in enumerate(hip_ids[-1])}
        # Chain vertices start at the crotch's front/back-centre v.
        top_v0 = np.array([v0[hip_col.get(int(vid), 0)] for vid in top_ids])
        b.add_block(np.array(ring_ids), top_v0, np.array(panels), anchors)
    pin = np.zeros(len(b.pos))
    pin[hip_ids[0]] = 1.0
    return b.finish(name, kind, pin)


class ArmAxis:
    """Centre line of one arm in the rest pose, shoulder joint -> elbow -> wrist (scene units),
    parametrised by the arc length t from the shoulder joint. The tangent turns from the upper
    arm's direction to the forearm's over `bend` either side of the elbow, so that rings
    perpendicular to it do not cross on the inside of the bend."""

    def __init__(self, shoulder, elbow, wrist, bend):
        self.joints = np.array([shoulder, elbow, wrist], np.float64)
        seg = np.diff(self.joints, axis=0)
        self.lengths = np.linalg.norm(seg, axis=1)
        self.dirs = seg / self.lengths[:, None]
        self.bend = bend
        # The centre line is the integral of the tangent, so it rounds the elbow (within a
        # few millimetres of the two segments); tabulated finely, interpolated in between.
        self._t = np.linspace(0.0, self.lengths.sum() * 1.5, 1001)
        tan = np.array([self.tangent(x) for x in self._t])
        steps = 0.5 * (tan[1:] + tan[:-1]) * np.diff(self._t)[:, None]
        self._p = self.joints[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])

    def point(self, t):
        """The point of the centre line at arc length t from the shoulder joint."""
        return np.array([np.interp(t, self._t, self._p[:, k]) for k in range(3)])

    def tangent(self, t):
        w = np.clip((t - self.lengths[0] + self.bend) / (2 * self.bend), 0.0, 1.0)
        w = w * w * (3 - 2 * w)
        d = (1 - w) * self.dirs[0] + w * self.dirs[1]
        return d / np.linalg.norm(d)

    def mirrored(self):
        """The other arm (x -> -x)."""
        flip = np.array([-1.0, 1.0, 1.0])
        j = self.joints * flip
        return ArmAxis(j[0], j[1], j[2], self.bend)


def _unit(v):
    return v / np.linalg.norm(v)


def _armhole_loop(ids, top_row, armpit_row, c_mid, half):
    """Vertex ids around the armhole cut into a torso grid `ids` (rows, cols): the columns
    c_mid - half .. c_mid + half between rows `top_row` and `armpit_row`. Starts at the
    hole's lower edge under the arm and goes round over the shoulder; index len // 2 is the
    top of the shoulder, so the sleeve's two panels meet under the arm and on top."""
    k, c0, c1 = armpit_row, c_mid - half, c_mid + half
    loop = [ids[k, c] for c in range(c_mid, c1 + 1)]
    loop += [ids[r, c1] for r in range(k - 1, top_row - 1, -1)]
    loop += [ids[top_row, c] for c in range(c1 - 1, c0 - 1, -1)]
    loop += [ids[r, c0] for r in range(top_row + 1, k + 1)]
    loop += [ids[k, c] for c in range(c0 + 1, c_mid)]
    return np.array(loop, np.int64)


def _sleeve_rings(b, profile, loop, axis, sleeve_t, offset_fn, blend_rings, slab, max_r, min_side_x, z_limit, spacing):
    """(len(sleeve_t) + 1, L) vertex ids of a sleeve: the armhole loop, then one ring per arc
    length in `sleeve_t` around `axis`, in the plane perpendicular to it. A ring's radius at
    each angle is the arm's cross-section in that plane (`profile.section`) plus offset_fn(t),
    or more for the first `blend_rings` rings, which narrow from the armhole's size to the
    arm's; the ring angles start at the loop's and even out over four rings (as the trouser
    legs do). z_limit: no ring point above it (scene units)."""
    pos = np.array(b.pos)
    up = np.array([0.0, 0.0, 1.0])
    c_loop = pos[loop].mean(0)
    n0 = axis.tangent(sleeve_t[0])
    e1_0 = _unit(up - (up @ n0) * n0)
    e2_0 = np.cross(n0, e1_0)
    d = pos[loop] - c_loop
    ang = np.unwrap(np.arctan2(d @ e2_0, d @ e1_0))
    L = len(loop)
    sign = 1.0 if ang[-1] > ang[0] else -1.0
    even = ang[0] + sign * 2 * math.pi * np.arange(L) / L
    ring_ids = [loop]
    for j, t in enumerate(sleeve_t, start=1):
        w = min(1.0, j / blend_rings)
        n = axis.tangent(t)
        c = axis.point(t)
        e1 = _unit(up - (up @ n) * n)
        e2 = np.cross(n, e1)
        a = ang + min(1.0, j / 4.0) * (even - ang)
        towards = np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2
        r = _sample(profile.section(c, n, e1, e2, slab, max_r, min_side_x), a) + offset_fn(t)
        # The armhole is larger than the arm (it reaches the neckline): the first rings shrink
        # towards the arm's section gradually, never inside it.
        blend = (1 - w) * pos[loop] + w * (c[None, :] + r[:, None] * towards) - c[None, :]
        r = np.maximum(r, np.linalg.norm(blend - np.outer(blend @ n, n), axis=1))
        # Nothing rises to the pinned neckline: the ring is pulled towards its centre there.
        up_z = towards[:, 2]
        over = (c[2] + r * up_z > z_limit) & (up_z > 0)
        r[over] = (z_limit - c[2]) / up_z[over]
        pts = c[None, :] + r[:, None] * towards
        if j == 1:
            # From the armhole to the first ring the strip can be long over the shoulder:
            # points on its straight rulings split it without changing its surface.
            n_split = int(math.ceil(np.linalg.norm(pts - pos[loop], axis=1).max() / (1.2 * spacing)))
            for i in range(1, n_split):
                ring_ids.append(b.add_vertices(pos[loop] + i / n_split * (pts - pos[loop])))
        ring_ids.append(b.add_vertices(pts))
    return np.array(ring_ids)


def _drop_unused(g):
    """Removes vertices no face uses (the cells cut out for armholes), keeping the order."""
    used = np.unique(g.faces)
    new_id = np.full(len(g.verts), -1, np.int64)
    new_id[used] = np.arange(len(used))
    return Garment(g.name, g.kind, g.verts[used], new_id[g.faces], g.uv, g.panel, g.pin[used])


def sleeved_garment(name, kind, profile, z_rows, hole_rows, offset_fn, hang_below, cols, arms, sleeve_t,
                    sleeve_offset_fn, hole_half, neck_deg, yoke_below, spacing, blend_rings=3, max_r=None,
                    min_side_x=None):
    """A top or jacket with two sleeves: a torso tube of horizontal rings from the neckline
    (row 0, pinned) to the hem, with an armhole cut into each side between the rows
    hole_rows = (top, armpit) (the columns within `hole_half` of 90 and 270 degrees), and a
    sleeve sewn into each armhole. The sleeve's first ring is the armhole itself; the next rings go
    round the arm axis at the arc lengths `sleeve_t` (the last one is the cuff).
    Rows above the armpits clear the body `yoke_below` downwards (the sloping shoulder tops)
    and include the arm roots, so the armholes' front and back edges stand off the shoulder.
    arms: {+1: ArmAxis of the left arm, -1: of the right arm}. A ring's arm section takes the
    body points within `max_r` of its centre (default 0.12 m, more than the arm's radius plus
    its bulges) and at least `min_side_x` from the midplane (default 0.14 m: the torso's sides
    under the arms are nearer, the arms farther).
    Panels: 0 front, 1 back (seams in the armholes and down the sides), then two per sleeve
    (its front and back halves, seams under the arm and on top)."""
    rows = len(z_rows)
    top_row, armpit_row = hole_rows
    q = cols // 4
    uniform = np.arange(cols) / cols * 2 * math.pi
    # On the neckline the armholes span only the shoulder top (+-neck_deg around the side);
    # the columns in front of and behind them spread to fill the rest of the ring.
    knots_c = np.array([0, q - hole_half, q + hole_half, 3 * q - hole_half, 3 * q + hole_half, cols])
    knots_a = np.radians([0, 90 - neck_deg, 90 + neck_deg, 270 - neck_deg, 270 + neck_deg, 360])
    neck_ang = np.interp(np.arange(cols), knots_c, knots_a)
    rings, prev = [], None
    for i, z in enumerate(z_rows):
        ang = neck_ang if i == 0 else uniform
        if i < armpit_row:
            # Never inside the plain torso hull (interpolated over empty bins, it can be the
            # larger one), so that an outer layer stays outside any inner layer's rows.
            hull = np.maximum(profile.hull(z, profile.arm_x, below=yoke_below), profile.hull(z, _max_x(z)))
        else:
            hull = profile.hull(z, _max_x(z))
            if prev is not None and z < hang_below:
                hull = np.maximum(hull, prev)
            prev = hull
        rings.append(_ring_point(profile.centre, ang, _sample(hull, ang) + offset_fn(z), z))
    rings = np.array(rings)
    b = _Builder()
    ids = b.add_vertices(rings.reshape(-1, 3)).reshape(rows, cols)
    keep = np.ones((rows - 1, cols), bool)
    for c_mid in (q, 3 * q):
        keep[top_row:armpit_row, c_mid - hole_half:c_mid + hole_half] = False
    panel_of_col = np.where((np.arange(cols) >= q) & (np.arange(cols) < 3 * q), 1, 0)
    b.add_block(ids, np.zeros(cols), panel_of_col, {0: 0, 1: q}, keep)
    slab = 0.6 * spacing
    max_r = 0.12 * SCENE_SCALE if max_r is None else max_r
    min_side_x = 0.14 * SCENE_SCALE if min_side_x is None else min_side_x
    for k, (side, c_mid) in enumerate(((1, q), (-1, 3 * q))):
        loop = _armhole_loop(ids, top_row, armpit_row, c_mid, hole_half)
        axis = arms[side]
        pos = np.array(b.pos)[loop]
        c = pos.mean(0)
        # The sleeve's rows run out along the arm: its columns must turn so that the faces
        # point away from the arm (as the torso's do), which fixes the loop's direction.
        a_dir = axis.tangent(sleeve_t[0])
        turn = np.einsum("ij,ij->i", np.cross(pos - c, np.roll(pos, -1, axis=0) - c), np.broadcast_to(a_dir, pos.shape))
        if turn.sum() > 0:
            loop = np.concatenate([loop[:1], loop[:0:-1]])
        sleeve = _sleeve_rings(b, profile, loop, axis, sleeve_t, sleeve_offset_fn, blend_rings, slab, max_r, min_side_x,
                               z_rows[0] - 0.005 * SCENE_SCALE, spacing)
        L = len(loop)
        p0, p1 = 2 + 2 * k, 3 + 2 * k
        b.add_block(sleeve, np.zeros(L), np.array([p0] * (L // 2) + [p1] * (L - L // 2)), {p0: 0, p1: L // 2})
    pin = np.zeros(len(b.pos))
    pin[ids[0]] = 1.0
    return _drop_unused(b.finish(name, kind, pin))
