"""Wind directions of the generator (numpy only, tested without Blender). A Blender wind
field blows along its local z axis; a pivot stores the field's rotation as a quaternion
(w, x, y, z). README "The wind" derives the strengths.
"""
import math

import numpy as np


def horizontal_wind_quaternion(rng, max_elevation_deg):
    """Unit quaternion (w, x, y, z) turning the field's z axis onto a direction of uniform yaw
    and elevation uniform in [-max, max] degrees from the ground plane."""
    return wind_quaternion(float(rng.uniform(0.0, 2.0 * math.pi)),
                           math.radians(float(rng.uniform(-max_elevation_deg, max_elevation_deg))))


def wind_quaternion(yaw, elevation):
    """Quaternion (w, x, y, z), w >= 0, of the shortest rotation taking +z onto the direction
    (cos e cos y, cos e sin y, sin e)."""
    d = np.array([math.cos(elevation) * math.cos(yaw), math.cos(elevation) * math.sin(yaw), math.sin(elevation)])
    axis = np.cross([0.0, 0.0, 1.0], d)
    n = np.linalg.norm(axis)
    angle = math.acos(max(-1.0, min(1.0, d[2])))
    axis = axis / n if n > 1e-12 else np.array([1.0, 0.0, 0.0])
    q = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])
    return q if q[0] >= 0 else -q


def wind_direction_of(q):
    """Direction (3,) the wind of quaternion q (w, x, y, z) blows to: q applied to +z."""
    w, x, y, z = q
    return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
