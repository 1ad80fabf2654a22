"""docs/stress.md from the ``results.csv`` of ``lss eval`` runs on stress sets.

    python -m lss_kernels.stress SET --seed 0                 # 36 scenes, 320x240
    lss eval SET --methods lss,sgm,bm-lr --out RESULTS
    python demos/stress_table.py RESULTS [RESULTS ...] > docs/stress.md

Each ``RESULTS`` folder (an ``lss eval --out``) is titled by the folder's name.  Folders of the
same scenes (two seeds of the stress set) share one section, each cell holding their numbers
in the order given (``0.98 / 0.99``): the mean occlusion F1 and bad-4.0 of every method per
family (the part of a scene's name before its first ``_``: ``periodic_fg_p3`` is of
``periodic``, ``random_07`` of ``random``), then per scene.  Nothing is typed in by hand:
rerun the evaluations and this script, and the page follows.
"""
import argparse
import csv
import math
import sys
from pathlib import Path

INTRO = """\
# The stress set

`python -m lss_kernels.stress DIR --seed S` renders hard two-layer scenes with exact ground
truth: nine families of four, 320×240 (`--random N`: N scenes drawn at random over the
generator's dimensions; each scene's `meta.json` holds its `family` and `description`).

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

Each section: `lss eval DIR --methods ... --out RESULTS` (default parameters, CPU), written
by `python demos/stress_table.py RESULTS ... > docs/stress.md`; occlusion F1 and bad-4.0 (%)
in the evaluation band (`docs/scene-format.md`).
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


def section(titles: list, runs: list) -> list:
    """The markdown lines of evaluations of the same scenes (``runs``, one ``{scene: {method:
    scores}}`` each): per family, then per scene; a cell holds each run's number."""
    scenes = list(runs[0])
    methods = list(dict.fromkeys(m for by_method in runs[0].values() for m in by_method))
    header = [f"F1 {m}" for m in methods] + [f"bad-4.0 {m}" for m in methods]

    def joined(values, digits):
        return " / ".join(number(v, digits) for v in values)

    def cells(group):
        f1 = [joined([mean(r[s][m][0] for s in group if m in r[s]) for r in runs], 2)
              for m in methods]
        bad = [joined([mean(r[s][m][1] for s in group if m in r[s]) for r in runs], 1)
               for m in methods]
        return f1 + bad

    def low(group):
        return " / ".join(str(sum(1 for s in group if "lss" in r[s] and r[s]["lss"][0] < 0.5))
                          for r in runs)

    lines = [f"## {', '.join(titles)}", ""]
    if len(runs) > 1:
        lines += [f"Each cell: {' / '.join(titles)}.", ""]
    groups = [(f, [s for s in scenes if family(s) == f])
              for f in dict.fromkeys(family(s) for s in scenes)]
    if len(groups) > 1:
        groups.append((f"all {len(scenes)}", scenes))
        lines += ["| family | n | " + " | ".join(header) + " | lss F1 < 0.5 |",
                  "|---" * (len(header) + 3) + "|"]
        lines += [f"| {name} | {len(group)} | " + " | ".join(cells(group)) + f" | {low(group)} |"
                  for name, group in groups]
        lines.append("")
    lines += ["| scene | " + " | ".join(header) + " |", "|---" * (len(header) + 1) + "|"]
    lines += [f"| {scene} | " + " | ".join(cells([scene])) + " |" for scene in scenes]
    if len(groups) == 1:
        lines.append(f"| mean of {len(scenes)} (lss F1 < 0.5: {low(scenes)}) | "
                     + " | ".join(cells(scenes)) + " |")
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path, metavar="RESULTS",
                        help="output folders of lss eval (each holds results.csv)")
    args = parser.parse_args(argv)
    sections = {}                       # the runs of the same scenes, in the order given
    for folder in args.results:
        scores = read_results(folder)
        titles, runs = sections.setdefault(tuple(scores), ([], []))
        titles.append(folder.resolve().name)
        runs.append(scores)
    lines = [INTRO]
    for titles, runs in sections.values():
        lines += section(titles, runs)
    sys.stdout.write("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
