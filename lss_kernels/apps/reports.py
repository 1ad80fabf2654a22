"""The reports of ``lss eval``: ``results.csv``, ``table.md`` (occlusion F1 per scene and
method beside a paper's), ``convergence.csv`` / ``.md`` / ``.png`` (with ``--trace``) and one
panel per scene (left image, truth and every method's disparity with its occlusions)."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .. import io
from ..stopping import replay

__all__ = ["COLUMNS", "MEAN_KEYS", "RULE_VARIANTS", "means", "write_convergence", "write_csv",
           "write_panel", "write_table"]

#: Columns of ``results.csv``.
#: ``bad4_surface``: bad-4.0 of the two quadratics before the refinement (lss; NaN for the
#: peers, which have no surface model).
#: ``flying``: percent of the band's cloud points off both true surfaces
#: (:mod:`lss_kernels.flying`).
COLUMNS = ("scene", "method", "occ_f1", "occ_precision", "occ_recall", "bad4", "bad4_surface",
           "flying", "seconds")
#: The columns averaged per method.
MEAN_KEYS = ("occ_f1", "occ_precision", "occ_recall", "bad4", "bad4_surface", "flying",
             "seconds")


def means(rows, method: str) -> dict:
    mine = [r for r in rows if r["method"] == method]
    return {k: float(np.mean([r.get(k, np.nan) for r in mine])) for k in MEAN_KEYS}


def write_csv(path: Path, rows, methods) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        for row in rows:
            writer.writerow([row["scene"], row["method"]]
                            + [f"{row.get(k, np.nan):.6g}" for k in COLUMNS[2:]])
        for method in methods:
            mean = means(rows, method)
            writer.writerow(["mean", method] + [f"{mean[k]:.6g}" for k in COLUMNS[2:]])


def _paper_label(key: str) -> str:
    return key if "paper" in key else f"{key} (paper)"


def write_table(path: Path, rows, names, methods, dataset_dir: Path) -> None:
    """Markdown table: rows = scenes, columns = occlusion F1 per method, then the paper's."""
    paper_file = dataset_dir / "paper_table1.json"
    paper = json.loads(paper_file.read_text()) if paper_file.exists() else {}
    numbers = {}
    for name in names:
        meta_file = dataset_dir / name / "meta.json"
        meta = json.loads(meta_file.read_text()) if meta_file.exists() else {}
        numbers[name] = meta.get("paper_scene")
    by_key = {(r["scene"], r["method"]): r for r in rows}
    fmt = lambda v, spec: "–" if v is None or v != v else format(v, spec)

    def paper_f1(key, name):
        n = numbers[name]
        table = paper[key]["occ_f1"]
        return table[n - 1] if n is not None and 1 <= n <= len(table) else None

    header = ["scene"] + list(methods) + [_paper_label(k) for k in paper]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name in names:
        label = name if numbers[name] is None else f"{numbers[name]}: {name}"
        cells = [fmt(by_key[name, m]["occ_f1"], ".2f") for m in methods]
        cells += [fmt(paper_f1(k, name), ".2f") for k in paper]
        lines.append("| " + " | ".join([label] + cells) + " |")
    by_method = {m: means(rows, m) for m in methods}
    paper_means = []
    for key in paper:
        values = [v for v in (paper_f1(key, n) for n in names) if v is not None]
        paper_means.append(float(np.mean(values)) if values else None)
    lines.append("| **mean F1** | " + " | ".join(
        [fmt(by_method[m]["occ_f1"], ".2f") for m in methods]
        + [fmt(v, ".2f") for v in paper_means]) + " |")
    lines.append("| **mean bad-4.0 (%)** | " + " | ".join(
        [fmt(by_method[m]["bad4"], ".2f") for m in methods]
        + [fmt(paper[k].get("avg_bad4"), ".2f") for k in paper]) + " |")
    lines.append("| **mean bad-4.0, two quadratics (%)** | " + " | ".join(
        [fmt(by_method[m]["bad4_surface"], ".2f") for m in methods] + ["–"] * len(paper))
        + " |")
    lines.append("| **mean flying pixels (% of the band's points)** | " + " | ".join(
        [fmt(by_method[m]["flying"], ".2f") for m in methods] + ["–"] * len(paper)) + " |")
    lines.append("| **seconds per scene** | " + " | ".join(
        [fmt(by_method[m]["seconds"], ".2f") for m in methods] + ["–"] * len(paper)) + " |")
    text = [f"# Occlusion F1 on {dataset_dir.name} ({len(names)} scenes)", ""] + lines
    if paper:
        text += ["", "Paper columns: Table 1 of the paper; their mean F1 is over the scenes "
                 "above, their mean bad-4.0 is the paper's own average over its 15 scenes."]
    for m in methods:
        text += ["", f"## {m}, per scene", "",
                 "| scene | occlusion F1 | precision | recall | bad-4.0 (%) | seconds | "
                 "iterations |", "|---|---|---|---|---|---|---|"]
        for name in names:
            r = by_key[name, m]
            text.append(f"| {name} | {r['occ_f1']:.2f} | {r['occ_precision']:.2f} | "
                        f"{r['occ_recall']:.2f} | {r['bad4']:.1f} | {r['seconds']:.1f} | "
                        f"{r.get('iterations', '–')} |")
        text.append(f"| **mean** | {by_method[m]['occ_f1']:.3f} | {by_method[m]['occ_precision']:.2f} | "
                    f"{by_method[m]['occ_recall']:.2f} | {by_method[m]['bad4']:.2f} | "
                    f"{by_method[m]['seconds']:.1f} | |")
    path.write_text("\n".join(text) + "\n")


#: Variants of the stopping rule that ``convergence.md`` replays, as multiples of the run's
#: ``stop_shift`` and ``min_iterations``.
RULE_VARIANTS = ((1.0, 1.0), (1.0, 0.5), (1.5, 1.0), (1.5, 0.5), (2.5, 1.0), (5.0, 1.0))


def write_convergence(out: Path, records, params, missing=()) -> None:
    """convergence.csv / .md / .png from the traces of ``lss`` runs (see ``run_eval``);
    ``missing``: the scenes whose lss run has no trace."""
    from .. import viz
    keys = ("iteration", "boundary_shift", "surface_change", "fg_fraction", "occ_f1", "bad4")
    with open(out / "convergence.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(("scene",) + keys)
        for r in records:
            for row in r["trace"]:
                # the shift and surface change are None in a run that ended before its
                # first window
                writer.writerow([r["scene"]] + ["" if row[k] is None else f"{row[k]:.6g}"
                                                for k in keys])

    last = max(r["trace"][-1]["iteration"] for r in records)
    # columns every ~100 iterations, on the recorded window ends
    step = params.stop_window * max(1, round(100 / params.stop_window))
    marks = list(range(step, last + 1, step))
    text = ["# Accuracy against iterations (lss)", "",
            f"Occlusion F1 every {step} iterations (blank: the run had stopped) and at the "
            "run's own stop.", "",
            "| scene | " + "".join(f"{m} | " for m in marks) + "stop | F1 |",
            "|---|" + "---|" * (len(marks) + 2)]
    for r in records:
        at = {row["iteration"]: row["occ_f1"] for row in r["trace"]}
        cells = "".join((f"{at[m]:.2f}" if m in at else "") + " | " for m in marks)
        text.append(f"| {r['scene']} | {cells}"
                    f"{r['trace'][-1]['iteration']} | {r['trace'][-1]['occ_f1']:.2f} |")
    if missing:
        text += ["", f"Not traced (finished by an earlier call without --trace; rerun them "
                     f"with --force): {', '.join(missing)}."]
    text += ["", "## Variants of the stopping rule, replayed on these runs", "",
             f"The runs used stop_shift {params.stop_shift}, min_iterations "
             f"{params.min_iterations}, stop_window {params.stop_window}, stop_patience "
             f"{params.stop_patience}. A variant can only be replayed up to where the run "
             "stopped: *ended* counts the runs whose record ended before the variant fired. "
             "bad-4.0 here is that of the two quadratics (the trace scores the model during "
             "the iterations, before the refinement).",
             "", "| stop_shift | min_iterations | median iterations | total iterations | "
             "mean F1 | mean bad-4.0 (%) | ended |", "|---|---|---|---|---|---|---|"]
    for f_scale, m_scale in RULE_VARIANTS:
        change = dict(stop_shift=params.stop_shift * f_scale,
                      min_iterations=max(1, int(params.min_iterations * m_scale)))
        stops = [replay(r["trace"], params, **change) for r in records]
        its = [e["iteration"] for e, _ in stops]
        text.append(f"| {change['stop_shift']:.4g} | {change['min_iterations']} | "
                    f"{np.median(its):.0f} | {sum(its)} | "
                    f"{np.mean([e['occ_f1'] for e, _ in stops]):.4f} | "
                    f"{np.mean([e['bad4'] for e, _ in stops]):.2f} | "
                    f"{sum(not fired for _, fired in stops)} |")
    (out / "convergence.md").write_text("\n".join(text) + "\n")

    fig = viz.new_figure(720, 420)
    ax = fig.add_axes((0.08, 0.12, 0.62, 0.8))
    for r in records:
        ax.plot([row["iteration"] for row in r["trace"]],
                [row["occ_f1"] for row in r["trace"]], label=r["scene"], linewidth=1)
    ax.set_xlabel("iteration")
    ax.set_ylabel("occlusion F1")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    viz.save_figure(fig, out / "convergence.png")


def write_panel(path: Path, scene_dir: Path, records, out: Path) -> None:
    """Left image, true disparity and each method's disparity with occlusions in dark blue."""
    from .. import viz
    scene = io.load_scene(scene_dir)
    truth = np.asarray(scene.disp_left, dtype=np.float32)
    finite = truth[np.isfinite(truth)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    vmax = max(vmax, vmin + 1.0)
    h, w = truth.shape
    tiles = [(scene.left, "left image"),
             (viz.occlusion_disparity_rgb(truth, scene.occ_left, vmin, vmax), "ground truth")]
    for record in records:
        run = out / "runs" / scene_dir.name / record["method"]
        disparity = io.read_pfm(run / "disparity.pfm")
        occlusion = io.read_mask(run / "occlusion.png")
        tiles.append((viz.occlusion_disparity_rgb(disparity, occlusion, vmin, vmax),
                      f"{record['method']}: F1 {record['occ_f1']:.2f}, "
                      f"bad-4.0 {record['bad4']:.1f} %"))
    tile_w = 320
    tile_h = max(1, round(tile_w * h / w))
    fig = viz.new_figure(tile_w * len(tiles), tile_h + 28)
    for i, (rgb, title) in enumerate(tiles):
        ax = fig.add_axes((i / len(tiles), 0, 1 / len(tiles), tile_h / (tile_h + 28)))
        ax.imshow(rgb, interpolation="nearest", aspect="auto")
        ax.set_axis_off()
        ax.set_title(title, fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    viz.save_figure(fig, path)
