#!/usr/bin/env python3
"""Freeze the part of a data set that exists, so that training can start while `layersnet
generate` is still adding sequences to it.

Writes OUT/dataset.json: the manifest of DATA as it is now, its training split cut to the
sequences whose files exist (validation is kept whole and must be complete; the test split is
kept whole when all its files exist and emptied otherwise, since training never reads it and it
is evaluated on DATA itself once complete), and links
every kept sequence file (and scene.json, if present) into OUT. The training split's statistics then come
from `layersnet prepare OUT`; a run trained on OUT keeps the same data when DATA grows. With
--max-train N only the first N of them (in the manifest's order) are kept, so that a frozen set
can be made again later, when more files exist.

Usage: freeze_train_split.py DATA OUT [--max-train N]
"""
import json
import os
import sys


def fail(message):
    print(f"freeze_train_split: {message}", file=sys.stderr)
    sys.exit(1)


def main(argv):
    max_train = None
    if len(argv) == 5 and argv[3] == "--max-train":
        if not argv[4].isdigit() or int(argv[4]) < 1:
            fail(f"--max-train {argv[4]}: give a positive whole number of training sequences")
        max_train = int(argv[4])
    elif len(argv) != 3:
        fail("usage: freeze_train_split.py DATA OUT [--max-train N]")
    data, out = (os.path.realpath(a) for a in argv[1:3])
    manifest_path = os.path.join(data, "dataset.json")
    try:
        with open(manifest_path) as f:
            manifest = json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{manifest_path}: cannot read the manifest ({e}); DATA must be a data-set folder")
    splits = manifest.get("splits")
    if not isinstance(splits, dict) or "train" not in splits:
        fail(f"{manifest_path}: no splits.train list; is this a data set written by layersnet generate?")
    def present(sid):
        return os.path.isfile(os.path.join(data, sid + ".h5"))

    dropped = []
    for name, ids in list(splits.items()):
        if name == "train":
            continue  # may be incomplete: cut below
        missing = [sid for sid in ids if not present(sid)]
        if name == "test" and missing:
            dropped.append(name)
            splits[name] = []
            continue
        if missing:
            fail(f"split {name} is incomplete ({len(missing)} of {len(ids)} files missing, e.g. {missing[0]}.h5); "
                 "generate it first (`layersnet generate ... --splits " + name + "`)")
    listed = len(splits["train"])
    kept_train = [sid for sid in splits["train"] if present(sid)][:max_train]
    if max_train is not None and len(kept_train) < max_train:
        fail(f"--max-train {max_train}: only {len(kept_train)} training sequences exist yet")
    if not kept_train:
        fail(f"{data}: no training sequence exists yet")
    if os.path.exists(os.path.join(out, "dataset.json")):
        fail(f"{out}/dataset.json exists; freeze into a new folder (a run's data must not change under it)")
    os.makedirs(out, exist_ok=True)
    manifest["splits"]["train"] = kept_train
    manifest["frozen_from"] = {"data": data, "train_sequences": len(kept_train),
                               "train_sequences_listed": listed}
    for sid in sorted({s for ids in manifest["splits"].values() for s in ids}):
        os.symlink(os.path.join(data, sid + ".h5"), os.path.join(out, sid + ".h5"))
    if os.path.isfile(os.path.join(data, "scene.json")):
        os.symlink(os.path.join(data, "scene.json"), os.path.join(out, "scene.json"))
    with open(os.path.join(out, "dataset.json"), "w") as f:
        json.dump(manifest, f, indent=2)
    print(f"freeze_train_split: {out}: {len(kept_train)} of the {listed} listed training sequences, "
          + ", ".join(f"{n} {len(ids)}" for n, ids in manifest["splits"].items() if n != "train")
          + "".join(f"; {n}: not all of its files exist yet, emptied" for n in dropped)
          + f"; next: layersnet prepare {out}")


if __name__ == "__main__":
    main(sys.argv)
