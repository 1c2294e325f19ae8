#!/usr/bin/env python3
"""check_figures.py passes a README whose figures match its report and fails one that does not."""
import gzip
import json
import pathlib
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
REPORT = {
    "methods": [
        {"name": "[constrained] LayersNet", "summary": {"error_mm": {"mean": 60.54, "std": 26.5}, "free_cloth_mm": 112.04,
                                                        "by_subset_mm": {"test_windy": {"mean": 70.26, "sequences": 3}}}},
        {"name": "[constrained] skinned to the body", "summary": {"error_mm": {"mean": 75.0, "std": 20.0}, "free_cloth_mm": 150.0}},
    ],
    "comparisons": [{"model": "[constrained] LayersNet", "baseline": "[constrained] skinned to the body",
                     "best_baseline": True, "ratio_of_means": 0.8072}],
}


def run(readme):
    with tempfile.TemporaryDirectory() as d:
        root = pathlib.Path(d)
        (root / "docs").mkdir()
        (root / "models").mkdir()
        (root / "models" / "eval.json").write_text(json.dumps(REPORT))
        (root / "models" / "eval.json.gz").write_bytes(gzip.compress(json.dumps(REPORT).encode()))
        (root / "README.md").write_text(readme)
        r = subprocess.run([sys.executable, str(HERE / "check_figures.py"), str(root)], capture_output=True, text=True)
        return r.returncode, r.stdout


TABLE = """# x

<!-- figures: models/eval.json -->
| method | error mm | free cloth mm | × best baseline |
|---|---|---|---|
| shipped (`[constrained] LayersNet`) | {err} ± 26.5 | 112.0 | 0.81 |
| [constrained] skinned to the body | 75.0 | 150 | – |
"""


def main():
    failures = []
    for report in ("eval.json", "eval.json.gz"):  # a report as written and gzipped
        table = TABLE.replace("models/eval.json", "models/" + report)
        code, out = run(table.format(err="60.5"))
        if code != 0:
            failures.append(f"matching figures of {report} were refused:\n" + out)
        code, out = run(table.format(err="59.9"))
        if code == 0 or "reads 59.9" not in out:
            failures.append(f"a wrong figure passed against {report}:\n" + out)
    code, out = run("# no table\n")
    if code == 0:
        failures.append("a README without a checked table passed")
    code, out = run(TABLE.format(err="60.5").replace("free cloth mm", "speed"))
    if code == 0:
        failures.append("an unknown column passed")
    code, out = run(TABLE.format(err="60.5").replace("models/eval.json", "models/missing.json"))
    if code == 0:
        failures.append("a missing report passed")
    subset = TABLE.format(err="60.5").replace("free cloth mm", "subset test_windy mm").replace("| 112.0 |", "| {w} |").replace("| 150 |", "| – |")
    code, out = run(subset.replace("{w}", "70.3"))
    if code != 0:
        failures.append("a matching subset figure was refused:\n" + out)
    code, out = run(subset.replace("{w}", "71.0"))
    if code == 0 or "reads 71.0" not in out:
        failures.append("a wrong subset figure passed:\n" + out)
    code, out = run(subset.replace("{w}", "70.3").replace("subset test_windy mm", "subset test_calm mm"))
    if code == 0 or "no subset 'test_calm'" not in out:
        failures.append("a subset the report lacks passed:\n" + out)
    for f in failures:
        print(f)
    print(f"test_check_figures: {10 - len(failures)} of 10 cases as expected")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
