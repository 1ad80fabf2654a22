"""Is lss's confidence worth anything?  Sparsification on a scored dataset, lss against SGBM's
left-right difference as its confidence.

Reads an ``lss eval`` output folder (its ``runs/<scene>/lss/`` hold ``disparity.pfm`` and
``confidence.pfm``) and the dataset it scored, runs SGBM again for its left-right
difference, and over the evaluation band's scored pixels (those of bad-4.0:
:mod:`lss_kernels.metrics`) reports

- per scene, bad-4.0 of the least confident 10 % and of the most confident 50 %, and their
  ratio (the criterion: >= 3);
- the pooled sparsification curve (bad-4.0 of the pixels kept against the fraction kept)
  of both methods, drawn into ``--plot``.

    lss eval DATASET --methods lss,sgm --out EVAL
    python demos/sparsification.py EVAL DATASET --plot docs/img/sparsification.png
"""
import argparse
import sys
from pathlib import Path

import numpy as np

from lss_kernels import io, metrics
from lss_kernels.apps.baselines import sgm_lr_difference
from lss_kernels.confidence import confidence_ratio, sparsification

#: The criterion: bad-4.0 of the least confident 10 % at least this many times that of the
#: most confident 50 %.
CRITERION = 3.0


def scene_pixels(scene_dir, eval_dir):
    """Per method, ``(confidence, bad)`` of the scene's scored pixels."""
    scene = io.load_scene(scene_dir)
    masks = metrics.evaluation_masks(scene)
    scored = masks["band"] & ~masks["true_occ"]
    truth = scene.disp_left.astype(np.float64)
    runs = Path(eval_dir) / "runs" / scene.name
    out = {}
    lss_d = io.read_pfm(runs / "lss" / "disparity.pfm")
    lss_c = io.read_pfm(runs / "lss" / "confidence.pfm")
    out["lss"] = lss_c[scored], ~(np.abs(lss_d - truth) <= metrics.BAD_THRESHOLD)[scored]
    sgm_d = io.read_pfm(runs / "sgm" / "disparity.pfm")
    lr = sgm_lr_difference(scene.left, scene.right, scene.d_max)
    out["sgm"] = -lr[scored], ~(np.abs(sgm_d - truth) <= metrics.BAD_THRESHOLD)[scored]
    return scene.name, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("eval_dir", help="an lss eval --methods lss,sgm output folder")
    parser.add_argument("dataset", help="the dataset it scored")
    parser.add_argument("--plot", help="PNG of the pooled sparsification curves")
    parser.add_argument("--title", default=None, help="the plot's title")
    args = parser.parse_args(argv)
    pooled = {"lss": ([], []), "sgm": ([], [])}
    print("| scene | lss: worst 10 % | best 50 % | ratio | SGBM LR: worst 10 % | best 50 % "
          "| ratio |")
    print("|---|---|---|---|---|---|---|")
    passed, counted = 0, 0
    for scene_dir in io.list_scenes(args.dataset):
        if not (Path(args.eval_dir) / "runs" / scene_dir.name / "lss" / "confidence.pfm"
                ).is_file():
            print(f"{scene_dir.name}: no lss confidence.pfm, left out", file=sys.stderr)
            continue
        name, per_method = scene_pixels(scene_dir, args.eval_dir)
        cells = []
        for method, (conf, bad) in per_method.items():
            pooled[method][0].append(conf)
            pooled[method][1].append(bad)
            ratio, worst, best = confidence_ratio(conf, bad)
            cells += [f"{worst:.1f}", f"{best:.2f}", f"{ratio:.1f}"]
            if method == "lss" and bad.any():
                counted += 1
                passed += worst >= CRITERION * best
        print(f"| {name} | " + " | ".join(cells) + " |")
    curves = {}
    for method, (conf, bad) in pooled.items():
        conf, bad = np.concatenate(conf), np.concatenate(bad)
        ratio, worst, best = confidence_ratio(conf, bad)
        print(f"| **pooled** {method} | {worst:.1f} | {best:.2f} | {ratio:.1f} |")
        curves[method] = sparsification(conf, bad)
    print(f"lss: worst 10 % >= {CRITERION:g} x best 50 % on {passed} of the {counted} scenes "
          f"with a bad pixel")
    print("| fraction kept | " + " | ".join(f"{f:.2f}" for f in curves["lss"][0][1::2]) + " |")
    for method, (fractions, rates) in curves.items():
        print(f"| {method} bad-4.0 (%) | " + " | ".join(f"{r:.2f}" for r in rates[1::2]) + " |")
    if args.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=120)
        labels = {"lss": "lss_kernels, its confidence", "sgm": "SGBM, left-right difference"}
        for method, (fractions, rates) in curves.items():
            ax.plot(100 * fractions, rates, marker="o", ms=3, label=labels[method])
        ax.set_xlabel("pixels kept, most confident first (%)")
        ax.set_ylabel("bad-4.0 of the pixels kept (%)")
        ax.set_title(args.title or f"Sparsification on {Path(args.dataset).name}")
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.plot)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
