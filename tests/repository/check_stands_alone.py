#!/usr/bin/env python3
"""The repository needs nothing beside it. In every tracked text file:
- a relative path ("../x/y", or a Markdown link target) must not climb out of the repository;
- an absolute path must not point into the folder that holds the clone;
- a Markdown link of a README or of docs/ must name a file that exists (generated reports,
  whose figures are not all kept, are exempt).
Logs (*.log) are records of the machine that wrote them, not references, and are exempt.
Prints one line per finding and exits 1 if there is any.
Usage: check_stands_alone.py REPOSITORY_ROOT"""
import os
import re
import subprocess
import sys
import tempfile

root = os.path.realpath(sys.argv[1])
parent = os.path.dirname(root)
# A clone in a scratch folder (/tmp, as CI may make it) has the scratch paths of the docs'
# examples "beside" it; those name no neighbour of the clone, so that test is skipped there.
SCRATCH = {"/tmp", "/var/tmp", os.path.realpath(tempfile.gettempdir())}
check_beside = parent != "/" and parent not in SCRATCH


def tracked_files():
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z"], check=True, capture_output=True).stdout
        return [f for f in out.decode().split("\0") if f]
    except (OSError, subprocess.CalledProcessError):  # a copy without .git: every file but builds and outputs
        skip = {"runs", "data", "logs", ".git"}
        files = []
        for d, dirs, names in os.walk(root):
            dirs[:] = [x for x in dirs if not (d == root and (x in skip or x.startswith("build")))]
            files += [os.path.relpath(os.path.join(d, n), root) for n in names]
        return files


def inside(path):
    return path == root or path.startswith(root + os.sep)


CLIMB = re.compile(r"(?<![\w.])((?:\.\./)+)([\w.-]+)")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
findings = []
for rel in tracked_files():
    path = os.path.join(root, rel)
    if rel.endswith(".log") or not os.path.isfile(path) or os.path.getsize(path) > 2_000_000:
        continue
    with open(path, "rb") as f:
        data = f.read()
    if b"\0" in data:
        continue  # binary
    text = data.decode("utf-8", errors="replace")
    here = os.path.dirname(path)
    for n, line in enumerate(text.splitlines(), 1):
        for m in CLIMB.finditer(line):
            if not inside(os.path.normpath(os.path.join(here, m.group(1) + m.group(2)))):
                findings.append(f"{rel}:{n}: {m.group(0)} leaves the repository")
        if check_beside and re.search(re.escape(parent) + r"/(?!" + re.escape(os.path.basename(root)) + r"\b)", line):
            findings.append(f"{rel}:{n}: an absolute path beside the repository")
        if not rel.endswith(".md"):
            continue
        for m in LINK.finditer(line):
            target = m.group(1).split("#")[0]
            if not target or re.match(r"^[a-z]+:", target):
                continue  # in-page anchor or URL
            resolved = os.path.normpath(os.path.join(here, target))
            if not inside(resolved):
                findings.append(f"{rel}:{n}: link {target} leaves the repository")
            elif (os.path.basename(rel) == "README.md" or rel.startswith("docs/")) and not os.path.exists(resolved):
                findings.append(f"{rel}:{n}: link {target} names no file")

for f in findings:
    print(f)
print(f"check_stands_alone: {len(findings)} finding(s)")
sys.exit(1 if findings else 0)
