#!/usr/bin/python3
"""Checks the procedural motion overlays and the wind directions without Blender: yaw rates
within the bound and piecewise constant, nothing before the overlays' start, hops that leave
and return to the ground at the drawn height, a generator that leaves other draws alone,
horizontal wind within the elevation bound and covering every yaw."""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../generate"))
import motion_blocks  # noqa: E402
import wind_field  # noqa: E402


def check_procedural():
    frames, start = 100, 21
    active = 0
    max_rate = 0.0
    for seed in range(200):
        p = motion_blocks.sample_procedural(np.random.default_rng(seed), {"probability": 0.6, "hop_probability": 1.0},
                                            frames, start)
        yaw, lift = np.array(p["yaw_deg"]), np.array(p["lift_m"])
        assert yaw.shape == (frames,) and lift.shape == (frames,)
        if not p["active"]:
            assert not yaw.any() and not lift.any() and p["arm_swing"] is None
            continue
        active += 1
        # Nothing moves before the overlays start (garments settle on the rest pose).
        assert not yaw[:start].any() and not lift[:start - 1].any(), seed
        rate = np.diff(yaw) * 30.0 / 360.0          # turns per second
        assert np.abs(rate).max() <= 1.5 + 1e-9, (seed, np.abs(rate).max())
        max_rate = max(max_rate, np.abs(rate).max())
        for first, end, r in p["turn_rates"]:
            seg = rate[first:min(end, frames - 1)]
            assert np.allclose(seg, r), (seed, first, end)
        # Hops: ballistic, at most the drawn maximum height, back on the ground by the end.
        assert lift.min() >= 0.0 and lift.max() <= 0.2 + 1e-9, seed
        assert lift.max() > 0.0, seed
    assert 90 < active < 150, active          # probability 0.6 of 200
    assert max_rate > 1.2, max_rate            # spins near the bound occur
    # Turning segments change abruptly: some neighbours differ by more than a turn per second.
    p = motion_blocks.sample_procedural(np.random.default_rng(1), {"probability": 1.0}, 400, 21)
    jumps = np.abs(np.diff([r for _, _, r in p["turn_rates"]]))
    assert jumps.max() > 0.5, jumps
    try:
        motion_blocks.sample_procedural(np.random.default_rng(0), {"spin": 1}, frames, start)
    except SystemExit as e:
        assert "unknown keys" in str(e)
    else:
        raise AssertionError("an unknown procedural key must be refused")


def check_wind():
    rng = np.random.default_rng(0)
    elev, yaw = [], []
    for _ in range(2000):
        q = wind_field.horizontal_wind_quaternion(rng, 30.0)
        assert abs(np.linalg.norm(q) - 1) < 1e-9 and q[0] >= 0
        d = wind_field.wind_direction_of(q)
        assert abs(np.linalg.norm(d) - 1) < 1e-9
        elev.append(math.degrees(math.asin(d[2])))
        yaw.append(math.degrees(math.atan2(d[1], d[0])) % 360)
    elev = np.array(elev)
    assert np.abs(elev).max() <= 30.0 + 1e-6 and np.abs(elev).max() > 29.0, np.abs(elev).max()
    counts = np.histogram(yaw, bins=8, range=(0, 360))[0]
    assert counts.min() > 150, counts                   # every yaw octant, about 250 each
    # The quaternion turns the field's +z axis onto the asked direction.
    for y, e in ((0.0, 0.0), (1.0, 0.4), (3.0, -0.5), (0.0, math.pi / 2)):
        d = wind_field.wind_direction_of(wind_field.wind_quaternion(y, e))
        want = [math.cos(e) * math.cos(y), math.cos(e) * math.sin(y), math.sin(e)]
        assert np.allclose(d, want), (y, e, d, want)


if __name__ == "__main__":
    check_procedural()
    check_wind()
    print("ok: procedural overlays and horizontal wind")
