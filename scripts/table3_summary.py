"""Gathers the Table 3 runs (scripts/table3_medium.sh) into one Markdown table.

Reads RUNS/<variant>_seed<k>/eval/eval.json and prints, per variant, every seed's figures and
their mean: error, layer and body collision rates, edge strain, and the ground truth's rates.
Usage: /usr/bin/python3 scripts/table3_summary.py RUNS
"""
import json
import pathlib
import statistics
import sys

VARIANTS = [("tie", "TIE"), ("vanilla", "vanilla RIA"), ("ria_ret", "RIA + RET")]
COLUMNS = [("error_mm", "error mm"), ("l_collision_outer_percent", "L-coll % (÷ outer)"),
           ("h_collision_percent", "H-coll %"), ("strain_mean_percent", "strain % mean"),
           ("strain_p99_percent", "strain % p99")]


def model_summary(eval_json, constrained):
    methods = json.loads(eval_json.read_text())["methods"]
    model = next(m for m in methods
                 if m["kind"] == "model" and m["name"].startswith("[constrained]") == constrained)
    truth = next(m for m in methods if m["name"] == "ground truth")
    return model["summary"], truth["summary"], model["diverged_sequences"]


def table(runs, constrained):
    header = "| variant | seed | " + " | ".join(c[1] for c in COLUMNS) + " | diverged |"
    title = "with the cloth constraints" if constrained else "the network alone (the paper's comparison)"
    lines = [f"## {title}", "", header, "|" + "---|" * (len(COLUMNS) + 3)]
    truth = None
    for key, label in VARIANTS:
        rows = []
        for path in sorted(runs.glob(f"{key}_seed*/eval/eval.json")):
            summary, truth, diverged = model_summary(path, constrained)
            seed = path.parent.parent.name.split("_seed")[-1]
            rows.append([summary[c]["mean"] for c, _ in COLUMNS])
            lines.append(f"| {label} | {seed} | " + " | ".join(f"{v:.2f}" for v in rows[-1]) + f" | {diverged} |")
        if len(rows) > 1:
            means = [statistics.mean(col) for col in zip(*rows)]
            spread = [max(col) - min(col) for col in zip(*rows)]
            lines.append(f"| **{label}** | mean (range) | " +
                         " | ".join(f"**{m:.2f}** ({s:.2f})" for m, s in zip(means, spread)) + " | |")
    if truth:
        lines.append("| ground truth | – | 0 | " + " | ".join(f"{truth[c]['mean']:.2f}" for c, _ in COLUMNS[1:]) + " | |")
    return lines


def main(runs):
    runs = pathlib.Path(runs)
    lines = ["# Paper Table 3 on the medium test split", ""]
    lines += table(runs, False) + [""] + table(runs, True)
    print("\n".join(lines))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: table3_summary.py RUNS")
    main(sys.argv[1])
