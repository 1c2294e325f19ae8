#!/usr/bin/env python3
"""The libraries form layers: a folder's sources include headers only from the folders below it,
so nothing runs back up, evaluation never needs the trainer, and the jobs built on evaluation
(bench, simulate, inspect) never need each other. Prints each include that
breaks the rule (file:line) and exits 1 if there is any.
Usage: check_layers.py REPOSITORY_ROOT"""
import os
import re
import sys

# folder -> the folders its sources may include (besides its own)
ALLOWED = {
    "autodiff": set(),
    "dataset": set(),
    "model": {"autodiff", "dataset"},
    "losses": {"autodiff", "dataset", "model"},
    "run": {"autodiff", "dataset", "model"},
    "train": {"autodiff", "dataset", "model", "losses", "run"},
    "eval": {"autodiff", "dataset", "model", "losses", "run"},
    # the jobs built on evaluation: none of them reaches into another or into the trainer
    "bench": {"autodiff", "dataset", "model", "losses", "run", "eval"},
    "simulate": {"autodiff", "dataset", "model", "losses", "run", "eval"},
    "inspect": {"autodiff", "dataset", "model", "losses", "run", "eval"},
}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([a-z_]+)/')

root = sys.argv[1]
bad = 0
for folder, allowed in ALLOWED.items():
    for dirpath, _, names in os.walk(os.path.join(root, folder)):
        for name in sorted(names):
            if not name.endswith((".h", ".cpp")):
                continue
            path = os.path.join(dirpath, name)
            with open(path, encoding="utf-8") as f:
                for number, line in enumerate(f, 1):
                    m = INCLUDE.match(line)
                    if m and m.group(1) != folder and m.group(1) in ALLOWED and m.group(1) not in allowed:
                        print(f"{os.path.relpath(path, root)}:{number}: {folder}/ must not include {m.group(1)}/ "
                              f"(allowed: {', '.join(sorted(allowed)) or 'nothing outside itself'})")
                        bad += 1
sys.exit(1 if bad else 0)
