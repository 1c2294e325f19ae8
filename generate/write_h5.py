"""Writes one sequence as D-LAYERS-H5 v1 (docs/dlayers-h5.md) with h5py.

The file is written to '<path>.tmp' and renamed, so a file at `path` is always complete.
"""
import os

import h5py
import numpy as np

_GZ = dict(compression="gzip", compression_opts=1, shuffle=True)


def write_sequence(path, seq):
    """seq: dict with fps, gravity (3,), scale, body {vertices (T,B,3), faces (Fb,3),
    translation (T,3), friction}, garments [ {name, type, vertices (T,N,3), faces (F,3),
    uv (F,3,2), panel (F,), rest (N,3), optional pin (N,) 0..1, attrs {...}} ] inner -> outer,
    wind {rotation (T,4), strength (T,)}, extra_attrs {...} (scalars / strings stored on the root)."""
    tmp = path + ".tmp"
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = "dlayers-h5"
        f.attrs["version"] = np.int32(1)
        f.attrs["fps"] = float(seq["fps"])
        f.attrs["up_axis"] = "z"
        f.attrs["gravity"] = np.asarray(seq["gravity"], np.float64)
        f.attrs["scale"] = float(seq["scale"])
        for k, v in seq.get("extra_attrs", {}).items():
            f.attrs[k] = v
        b = f.create_group("body")
        T = seq["body"]["vertices"].shape[0]
        b.create_dataset("vertices", data=seq["body"]["vertices"].astype(np.float32),
                         chunks=(1,) + seq["body"]["vertices"].shape[1:], **_GZ)
        b.create_dataset("faces", data=seq["body"]["faces"].astype(np.int32))
        b.create_dataset("translation", data=seq["body"]["translation"].astype(np.float32))
        b.attrs["friction"] = float(seq["body"]["friction"])
        g = f.create_group("garments")
        g.attrs["order"] = np.array([x["name"] for x in seq["garments"]], dtype=h5py.string_dtype())
        for gar in seq["garments"]:
            gg = g.create_group(gar["name"])
            gg.create_dataset("vertices", data=gar["vertices"].astype(np.float32),
                              chunks=(1,) + gar["vertices"].shape[1:], **_GZ)
            gg.create_dataset("faces", data=gar["faces"].astype(np.int32))
            gg.create_dataset("uv", data=gar["uv"].astype(np.float32))
            gg.create_dataset("panel", data=gar["panel"].astype(np.int32))
            gg.create_dataset("rest", data=gar["rest"].astype(np.float32))
            if gar.get("pin") is not None:
                pin = np.asarray(gar["pin"], np.float32)
                assert pin.shape == gar["vertices"].shape[1:2], "pin needs one weight per vertex"
                gg.create_dataset("pin", data=pin)
            gg.attrs["type"] = gar["type"]
            for k, v in gar["attrs"].items():
                gg.attrs[k] = float(v)
        w = f.create_group("wind")
        w.create_dataset("rotation", data=seq["wind"]["rotation"].astype(np.float32))
        w.create_dataset("strength", data=seq["wind"]["strength"].astype(np.float32))
        assert w["strength"].shape[0] == T
    os.replace(tmp, path)
