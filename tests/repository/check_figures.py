#!/usr/bin/env python3
"""Every figure a results table in README.md or docs/*.md states comes from a report committed in
the repository.

A checked table follows a marker line naming the report it was read from:

    <!-- figures: models/medium/eval/eval.json.gz -->
    | method | error mm | free cloth mm | x best baseline |
    |---|---|---|---|
    | [constrained] LayersNet | 60.5 ± 26.5 | 112.0 | 0.80 |

A report may be stored gzipped (a name ending in .gz). The first column is the method's name in
the report (markdown emphasis is ignored; a name in
backticks inside the cell is used when present, so a row may read "shipped (`[constrained] X`)").
Every other column must be one this script knows (COLUMNS); each number must equal the report's
within half a unit of its last printed digit; a cell "–" states nothing. A table whose column is unknown, a method missing
from the report, a report that does not exist or a README without any checked table fails.
Usage: check_figures.py REPOSITORY_ROOT
"""
import gzip
import json
import pathlib
import re
import sys

MARKER = re.compile(r"<!--\s*figures:\s*(\S+)\s*-->")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def summary(key, stat="mean"):
    def get(report, method):
        value = method["summary"][key]
        return value[stat] if isinstance(value, dict) else value
    return get


def comparison(field, best=True):
    def get(report, method):
        for c in report.get("comparisons", []):
            if c["model"] == method["name"] and c["best_baseline"] == best:
                return c[field]
        raise KeyError(f"no comparison of '{method['name']}' with its best baseline")
    return get


# column header (lower case, spaces collapsed) -> (value getter, index of the number in the cell)
COLUMNS = {
    "error mm": (summary("error_mm"), 0),
    "error mm (± std)": (summary("error_mm"), 0),
    "near body mm": (summary("near_body_mm"), 0),
    "free cloth mm": (summary("free_cloth_mm"), 0),
    "h-coll %": (summary("h_collision_percent"), 0),
    "l-coll %": (summary("l_collision_outer_percent"), 0),
    "strain %": (summary("strain_mean_percent"), 0),
    "strain p99 %": (summary("strain_p99_percent"), 0),
    "crumple °": (summary("dihedral_mean_deg"), 0),
    "crumple at the mark °": (summary("dihedral_at_mark_deg"), 0),
    "crumple at the end °": (summary("dihedral_end_deg"), 0),
    "error to the mark mm": (summary("error_to_mark_mm"), 0),
    "× best baseline": (comparison("ratio_of_means"), 0),
    "free cloth × best baseline": (comparison("free_cloth_ratio_of_means"), 0),
    "per-sequence median ×": (comparison("median_ratio"), 0),
    "worst sequence ×": (comparison("worst_ratio"), 0),
}


SUBSET_COLUMN = re.compile(r"^subset (\S+) mm$")  # "subset test_windy mm": by_subset_mm["test_windy"]


def column(header):
    """The (getter, index) of a column header, or None when check_figures.py does not know it."""
    if header in COLUMNS:
        return COLUMNS[header]
    m = SUBSET_COLUMN.match(header)
    if m:
        name = m.group(1)

        def get(report, method):
            # Headers are compared in lower case; subset names keep theirs (D-LAYERS' "T+W").
            subsets = {k.lower(): v for k, v in method["summary"].get("by_subset_mm", {}).items()}
            if name not in subsets:
                raise KeyError(f"no subset '{name}' in the summary of '{method['name']}'")
            return subsets[name]["mean"]
        return get, 0
    return None


def cells(line):
    return [c.strip() for c in line.strip().strip("|").split("|")]


def method_name(cell):
    quoted = re.findall(r"`([^`]+)`", cell)
    return quoted[-1] if quoted else cell.replace("**", "").replace("*", "").strip()


def check_table(doc, lines, start, report_path, root, problems):
    path = root / report_path
    where = f"{doc}:{start + 1}"
    if not path.is_file():
        problems.append(f"{where}: the table names {report_path}, which is not in the repository")
        return
    text = gzip.decompress(path.read_bytes()).decode() if path.suffix == ".gz" else path.read_text()
    report = json.loads(text)
    methods = {m["name"]: m for m in report["methods"]}
    i = start + 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines) or not lines[i].lstrip().startswith("|"):
        problems.append(f"{where}: a figures marker must be followed by a table")
        return
    header = [re.sub(r"\s+", " ", h.lower()) for h in cells(lines[i])]
    for h in header[1:]:
        if column(h) is None:
            problems.append(f"{doc}:{i + 1}: column '{h}' is not one check_figures.py knows ({', '.join(COLUMNS)}, "
                            "or 'subset NAME mm')")
            return
    i += 2  # the header's separator row
    rows = 0
    while i < len(lines) and lines[i].lstrip().startswith("|"):
        row = cells(lines[i])
        name = method_name(row[0])
        if name not in methods:
            problems.append(f"{doc}:{i + 1}: '{name}' is not a method of {report_path}")
            i += 1
            continue
        for h, cell in zip(header[1:], row[1:]):
            if cell in ("–", "-", ""):  # not applicable to this row
                continue
            numbers = NUMBER.findall(cell)
            getter, k = column(h)
            if len(numbers) <= k:
                problems.append(f"{doc}:{i + 1}: column '{h}' of '{name}' holds no number")
                continue
            text = numbers[k]
            decimals = len(text.split(".")[1]) if "." in text else 0
            try:
                expected = getter(report, methods[name])
            except KeyError as e:
                problems.append(f"{doc}:{i + 1}: {e.args[0]} in {report_path}")
                continue
            if abs(float(text) - expected) > 0.5 * 10 ** -decimals + 1e-9:
                problems.append(f"{doc}:{i + 1}: '{name}' {h} reads {text}, {report_path} has {expected:.{decimals + 2}f}")
        rows += 1
        i += 1
    if rows == 0:
        problems.append(f"{where}: the checked table has no rows")


def main(root):
    root = pathlib.Path(root)
    problems, tables, readme_tables = [], 0, 0
    for doc in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        lines = doc.read_text().splitlines()
        rel = doc.relative_to(root)
        for n, line in enumerate(lines):
            m = MARKER.search(line)
            if m:
                tables += 1
                readme_tables += doc.name == "README.md"
                check_table(rel, lines, n, m.group(1), root, problems)
    if readme_tables == 0:
        problems.append("README.md: no results table carries a '<!-- figures: REPORT -->' marker, so none is checked")
    for p in problems:
        print(p)
    print(f"check_figures: {tables} table(s) checked, {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "."))
