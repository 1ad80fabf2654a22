"""Flying points of lss's cloud when only its confident points are kept.

Reads an ``lss eval`` output folder (its ``runs/<scene>/lss/`` hold ``disparity.pfm``,
``occlusion.png`` and ``confidence.pfm``) and the dataset it scored, and for each
``min_confidence`` (:func:`lss_kernels.cloud.select`, ``Result.points``) prints the mean
share of flying points over the scenes (:mod:`lss_kernels.flying`: the evaluation band's
cloud points more than 1 px from both true surfaces), the share of the band's pixels the
cloud keeps, and the scenes at or under 1 %.

    lss eval DATASET --methods lss --out EVAL
    python demos/confident_cloud.py EVAL DATASET
"""
import argparse
import sys
from pathlib import Path

import numpy as np

from lss_kernels import io, metrics
from lss_kernels.cloud import select
from lss_kernels.flying import flying_pixels

THRESHOLDS = (0.0, 0.05, 0.1, 0.2)


def scene_shares(scene_dir, eval_dir, thresholds=THRESHOLDS):
    """Per threshold, ``(flying %, kept %)`` of one scene."""
    scene = io.load_scene(scene_dir)
    band = metrics.evaluation_masks(scene)["band"]
    run = Path(eval_dir) / "runs" / scene.name / "lss"
    disparity = io.read_pfm(run / "disparity.pfm")
    occlusion = io.read_mask(run / "occlusion.png")
    confidence = io.read_pfm(run / "confidence.pfm")
    shares = []
    for threshold in thresholds:
        points = band & select("all", np.zeros_like(band), occlusion, confidence, threshold)
        flying = flying_pixels(disparity, points, scene.disp_left, scene.fg_left)
        shares.append((100.0 * flying.sum() / max(points.sum(), 1),
                       100.0 * points.sum() / max(band.sum(), 1)))
    return shares


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("eval_dir", help="an lss eval output folder with lss's runs")
    parser.add_argument("dataset", help="the dataset it scored")
    args = parser.parse_args(argv)
    scenes = sorted(p for p in Path(args.dataset).iterdir()
                    if (Path(args.eval_dir) / "runs" / p.name / "lss" / "confidence.pfm").is_file())
    if not scenes:
        print(f"eval_dir: no lss runs with confidence.pfm in {args.eval_dir}", file=sys.stderr)
        return 2
    shares = np.array([scene_shares(s, args.eval_dir) for s in scenes])   # scene, thr, 2
    print(f"{len(scenes)} scenes")
    print("| min_confidence | flying (mean %) | band points kept (%) | scenes <= 1 % |")
    print("|---|---|---|---|")
    for k, threshold in enumerate(THRESHOLDS):
        fly, kept = shares[:, k, 0], shares[:, k, 1]
        print(f"| {threshold:g} | {fly.mean():.1f} | {kept.mean():.0f} | {(fly <= 1.0).sum()} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
