#!/usr/bin/python3
"""How hard the data's wind pushes the cloth, next to gravity and the cloth's own acceleration.

For each windy file, over the frames after the ramp whose stored strength is above --above:
Blender's wind acceleration of every unpinned garment vertex, F / m with F the face wind
(each triangle of area A gives each corner 0.02 A / 3 (w.n) n, w = strength x wind_field_factor x
direction / fps: the law `losses/physics.h` states) and m the garment's vertex mass; gravity's
0.001 g; and the cloth's own acceleration x_{t+1} - 2 x_t + x_{t-1} relative to the body root.
Accelerations in mm per frame squared (10 scene units per metre). Needs python3-h5py and numpy.

Usage: wind_acceleration.py FILE.h5 [FILE.h5 ...] [--above S]
"""
import argparse

import h5py
import numpy as np


def wind_direction(q):
    """R(q) (0, 0, 1) for a (w, x, y, z) quaternion."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def face_wind(positions, faces, wind):
    """Per-vertex face wind (N, 3) of Blender's cloth solver for the wind vector `wind`."""
    cross = np.cross(positions[faces[:, 1]] - positions[faces[:, 0]], positions[faces[:, 2]] - positions[faces[:, 0]])
    length = np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(length, 1e-12)[:, None]
    corner = (0.02 * (length / 2) / 3 * (normal @ wind))[:, None] * normal
    force = np.zeros_like(positions)
    for c in range(3):
        np.add.at(force, faces[:, c], corner)
    return force


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="+", metavar="FILE.h5")
    parser.add_argument("--above", type=float, default=50.0, help="keep frames whose wind strength is above this (default 50)")
    args = parser.parse_args()
    mm = 100.0  # scene units (10 per metre) to mm
    for path in args.files:
        with h5py.File(path, "r") as f:
            if "wind" not in f:
                print(f"{path}: no wind")
                continue
            fps = float(f.attrs["fps"])
            factor = float(f.attrs.get("wind_field_factor", 1.0))
            gravity = 1e-3 * np.linalg.norm(f.attrs["gravity"]) * mm
            first = int(f.attrs.get("ramp_frames", 0)) + int(f.attrs.get("rest_frames", 0))
            rotation, strength = f["wind/rotation"][()], f["wind/strength"][()]
            root = f["body/translation"][()]
            wind_acc, cloth_acc = [], []
            for name in f["garments"].attrs["order"]:
                garment = f["garments/" + name]
                x, faces, mass = garment["vertices"][()], garment["faces"][()], float(garment.attrs["mass"])
                free = garment["pin"][()] < 0.5
                for t in range(max(first, 1), x.shape[0] - 1):
                    if strength[t] <= args.above:
                        continue
                    wind = strength[t] * factor / fps * wind_direction(rotation[t])
                    wind_acc.append(np.linalg.norm(face_wind(x[t], faces, wind)[free], axis=1) / mass * mm)
                    rel = [x[k] - root[k] for k in (t - 1, t, t + 1)]
                    cloth_acc.append(np.linalg.norm((rel[2] - 2 * rel[1] + rel[0])[free], axis=1) * mm)
            if not wind_acc:
                print(f"{path}: no frame after the ramp with wind above {args.above:g}")
                continue
            wa, ca = np.concatenate(wind_acc), np.concatenate(cloth_acc)
            print(f"{path}: wind {wa.mean():.2f} mm/frame^2 (p90 {np.percentile(wa, 90):.2f}), "
                  f"{wa.mean() / gravity:.1f}x gravity's {gravity:.2f}; cloth {ca.mean():.2f} (p90 {np.percentile(ca, 90):.2f}); "
                  f"{len(wind_acc) // len(f['garments'].attrs['order'])} frames")


if __name__ == "__main__":
    main()
