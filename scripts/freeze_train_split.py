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
can be made again later, when more files exist. Each --add OTHER[:N] also links the training
sequences of another data set (those whose files exist, or the first N of them) into the training
split, named OTHER's folder name, an underscore and their own name, with their tags: one run then
trains on both (validation and test stay DATA's).

Usage: freeze_train_split.py DATA OUT [--max-train N] [--add OTHER[:N]]...
"""
import json
import os
import sys


def fail(message):
    print(f"freeze_train_split: {message}", file=sys.stderr)
    sys.exit(1)


def positive_count(text, what):
    if not text.isdigit() or int(text) < 1:
        fail(f"{what}: give a positive whole number of training sequences")
    return int(text)


def read_manifest(folder):
    path = os.path.join(folder, "dataset.json")
    try:
        with open(path) as f:
            manifest = json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{path}: cannot read the manifest ({e}); it must be a data-set folder")
    if not isinstance(manifest.get("splits"), dict) or "train" not in manifest["splits"]:
        fail(f"{path}: no splits.train list; is this a data set written by layersnet generate?")
    return manifest


def main(argv):
    usage = "usage: freeze_train_split.py DATA OUT [--max-train N] [--add OTHER[:N]]..."
    if len(argv) < 3 or argv[1].startswith("--") or argv[2].startswith("--"):
        fail(usage)
    max_train, added = None, []
    rest = argv[3:]
    while rest:
        if len(rest) < 2 or rest[0] not in ("--max-train", "--add"):
            fail(usage)
        flag, value, rest = rest[0], rest[1], rest[2:]
        if flag == "--max-train":
            max_train = positive_count(value, "--max-train")
        else:
            path, _, count = value.partition(":")
            added.append((os.path.realpath(path), positive_count(count, f"--add {value}") if count else None))
    data, out = (os.path.realpath(a) for a in argv[1:3])
    manifest = read_manifest(data)
    splits = manifest["splits"]
    def present(sid, folder=data):
        return os.path.isfile(os.path.join(folder, sid + ".h5"))

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
    links = {sid: os.path.join(data, sid + ".h5") for name, ids in splits.items() if name != "train" for sid in ids}
    links.update({sid: os.path.join(data, sid + ".h5") for sid in kept_train})
    own_train = len(kept_train)
    added_record = []
    for other, count in added:
        other_manifest = read_manifest(other)
        other_ids = [sid for sid in other_manifest["splits"]["train"] if present(sid, other)][:count]
        if count is not None and len(other_ids) < count:
            fail(f"--add {other}:{count}: only {len(other_ids)} training sequences exist there yet")
        if not other_ids:
            fail(f"--add {other}: no training sequence exists there yet")
        prefix = os.path.basename(other) + "_"
        tags = manifest.setdefault("tags", {})
        for sid, tag in other_manifest.get("tags", {}).items():
            if sid in other_ids:
                tags[prefix + sid] = tag
        for sid in other_ids:
            if prefix + sid in links:
                fail(f"--add {other}: the name {prefix + sid} is taken twice; add each data set once")
            links[prefix + sid] = os.path.join(other, sid + ".h5")
            kept_train.append(prefix + sid)
        added_record.append({"data": other, "train_sequences": len(other_ids)})
    os.makedirs(out, exist_ok=True)
    manifest["splits"]["train"] = kept_train
    manifest["frozen_from"] = {"data": data, "train_sequences": own_train, "train_sequences_listed": listed}
    if added_record:
        manifest["frozen_from"]["added"] = added_record
    for sid in sorted(links):
        os.symlink(links[sid], os.path.join(out, sid + ".h5"))
    if os.path.isfile(os.path.join(data, "scene.json")):
        os.symlink(os.path.join(data, "scene.json"), os.path.join(out, "scene.json"))
    with open(os.path.join(out, "dataset.json"), "w") as f:
        json.dump(manifest, f, indent=2)
    print(f"freeze_train_split: {out}: {own_train} of the {listed} listed training sequences, "
          + "".join(f"{a['train_sequences']} added from {a['data']}, " for a in added_record)
          + ", ".join(f"{n} {len(ids)}" for n, ids in manifest["splits"].items() if n != "train")
          + "".join(f"; {n}: not all of its files exist yet, emptied" for n in dropped)
          + f"; next: layersnet prepare {out}")


if __name__ == "__main__":
    main(sys.argv)
