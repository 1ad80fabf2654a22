"""docs/stress.md from the ``results.csv`` of ``lss eval`` runs on stress sets.

    python -m lss_kernels.stress SET --seed 0                 # 36 scenes, 320x240
    lss eval SET --methods lss,sgm,bm-lr --out RESULTS
    python demos/stress_table.py RESULTS [RESULTS ...] > docs/stress.md

Each ``RESULTS`` folder (an ``lss eval --out``) becomes one section, titled by the folder's
name: the mean occlusion F1 and bad-4.0 of every method per family (the part of a scene's
name before its first ``_``: ``periodic_fg_p3`` is of ``periodic``, ``random_07`` of
``random``), then per scene.  Nothing is typed in by hand: rerun the evaluations and this
script, and the page follows.
"""
import argparse
import csv
import math
import sys
from pathlib import Path

INTRO = """\
# The stress set

`python -m lss_kernels.stress DIR --seed S` renders hard two-layer scenes with exact ground
truth (`lss_kernels.stress`: nine families of four, 320×240; `--random N` draws N scenes at
random over the generator's dimensions instead; each scene's `meta.json` holds its `family`
and a one-line `description`). The families:

| family | what it tests |
|---|---|
| `periodic` | vertical stripes (period 3–8 px) on the foreground, the background or both |
| `camouflage` | both layers drawn from the same texture statistics |
| `weak` | low contrast: a few grey levels of texture, mid-grey or dark |
| `curved` | curved backgrounds: a bowl, cylinders along x and y, a dark weakly textured ball |
| `jump` | the foreground 40–60 px nearer than the background: wide occlusion strips |
| `init` | poor hand ellipses: half the object, or spilling 30 % beyond it |
| `shape` | non-elliptic outlines: a rectangle, an L, a blob |
| `fine` | small disparity jumps: occlusion strips 3–7 px wide |
| `clutter` | boxes, a shelf, a floor behind the object that one quadratic cannot follow |

Each section below is one `lss eval DIR --methods ... --out RESULTS` with the default
parameters, on the CPU; this page is written by `python demos/stress_table.py RESULTS ... >
docs/stress.md` from their `results.csv`. Scores follow `docs/scene-format.md`: occlusion
F1 and bad-4.0 (%) in the evaluation band; "F1 < 0.5" counts lss's scenes below 0.5.
"""


def read_results(folder: Path) -> dict:
    """``{scene: {method: (occ_f1, bad4)}}`` from ``folder/results.csv`` (the mean rows left
    out), scenes in the file's order."""
    path = folder / "results.csv"
    if not path.is_file():
        raise SystemExit(f"stress_table: RESULTS: expected a folder with results.csv, got "
                         f"{folder}")
    scores = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row["scene"] != "mean":
                scores.setdefault(row["scene"], {})[row["method"]] = (
                    float(row["occ_f1"]), float(row["bad4"]))
    return scores


def family(scene: str) -> str:
    return scene.split("_", 1)[0]


def mean(values) -> float:
    values = [v for v in values if not math.isnan(v)]
    return sum(values) / len(values) if values else math.nan


def number(value: float, digits: int) -> str:
    return "–" if math.isnan(value) else f"{value:.{digits}f}"


def section(title: str, scores: dict) -> list:
    """The markdown lines of one evaluation: per family, then per scene."""
    methods = list(dict.fromkeys(m for by_method in scores.values() for m in by_method))
    header = ([f"F1 {m}" for m in methods] + [f"bad-4.0 {m}" for m in methods])

    def cells(scenes):
        f1 = [mean(scores[s][m][0] for s in scenes if m in scores[s]) for m in methods]
        bad = [mean(scores[s][m][1] for s in scenes if m in scores[s]) for m in methods]
        return [number(v, 2) for v in f1] + [number(v, 1) for v in bad]

    families = list(dict.fromkeys(family(s) for s in scores))
    lines = [f"## {title}", "", f"Per family (means over its scenes; {len(scores)} scenes):",
             "", "| family | n | " + " | ".join(header) + " | lss F1 < 0.5 |",
             "|---" * (len(header) + 3) + "|"]
    groups = [(f, [s for s in scores if family(s) == f]) for f in families]
    if len(groups) > 1:
        groups.append((f"all {len(scores)}", list(scores)))
    for name, scenes in groups:
        low = sum(1 for s in scenes if "lss" in scores[s] and scores[s]["lss"][0] < 0.5)
        lines.append(f"| {name} | {len(scenes)} | " + " | ".join(cells(scenes))
                     + f" | {low} |")
    lines += ["", "Per scene:", "", "| scene | " + " | ".join(header) + " |",
              "|---" * (len(header) + 1) + "|"]
    for scene in scores:
        lines.append(f"| {scene} | " + " | ".join(cells([scene])) + " |")
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path, metavar="RESULTS",
                        help="output folders of lss eval (each holds results.csv)")
    args = parser.parse_args(argv)
    lines = [INTRO]
    for folder in args.results:
        lines += section(folder.resolve().name, read_results(folder))
    sys.stdout.write("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
