#!/usr/bin/env python3
"""The repository carries the product, not the experiments: every tracked file larger than the
file limit must be a shipped model's weights (models/<name>/model.h5), and all tracked files
together must stay within the total limit. Sizes are the files' bytes in the work tree (what
`git ls-files | xargs du -cb` adds up). Prints the largest files and exits 1 on a breach.
Usage: check_size.py REPOSITORY_ROOT [--max-file-mb 5] [--max-total-mb 20]"""
import argparse
import fnmatch
import os
import subprocess
import sys

parser = argparse.ArgumentParser()
parser.add_argument("root")
parser.add_argument("--max-file-mb", type=float, default=5.0)
parser.add_argument("--max-total-mb", type=float, default=20.0)
args = parser.parse_args()
root = os.path.realpath(args.root)
MB = 1_000_000
SHIPPED_WEIGHTS = "models/*/model.h5"

try:
    out = subprocess.run(["git", "-C", root, "ls-files", "-z"], check=True, capture_output=True).stdout
except (OSError, subprocess.CalledProcessError) as e:
    print(f"check_size: {root} is not a git work tree ({e}); the size check needs the tracked file list")
    sys.exit(1)
files = [f for f in out.decode().split("\0") if f]
sizes = {f: os.path.getsize(os.path.join(root, f)) for f in files if os.path.isfile(os.path.join(root, f))}
total = sum(sizes.values())
findings = []
for f, size in sorted(sizes.items(), key=lambda kv: -kv[1]):
    if size > args.max_file_mb * MB and not fnmatch.fnmatch(f, SHIPPED_WEIGHTS):
        findings.append(f"{f}: {size / MB:.1f} MB, over {args.max_file_mb:g} MB and not a shipped model "
                        f"({SHIPPED_WEIGHTS}); keep its figures in docs/decisions.md with the command and untrack it")
if total > args.max_total_mb * MB:
    findings.append(f"the tracked tree holds {total / MB:.1f} MB, over {args.max_total_mb:g} MB; "
                    "experiment weights, logs and data belong outside the repository")
print(f"check_size: {len(sizes)} tracked files, {total / MB:.2f} MB; largest:")
for f, size in sorted(sizes.items(), key=lambda kv: -kv[1])[:5]:
    print(f"  {size / MB:7.2f} MB  {f}")
for f in findings:
    print(f)
sys.exit(1 if findings else 0)
