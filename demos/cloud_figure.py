"""The object's point cloud from lss next to SGBM's, from the same pair and one viewpoint.

Reads an ``lss eval --methods lss,sgm`` output folder (each run's ``disparity.pfm`` and
``occlusion.png``) and the scene folder it scored.  Each method's cloud holds its
non-occluded pixels around the object (the true foreground's bounding box widened by
``--margin`` pixels: the object and the wall beside it), coloured by the left image, in
the limits of the true cloud (points beyond them are not drawn); the
points whose disparity lies more than 1 px off both true surfaces
(:mod:`lss_kernels.flying`) are drawn in red.  Seen from above and to the side, a flying
point hangs between the object and the wall.

The scene folders carry no calibration: depth is drawn for ``focal = width`` pixels and a
baseline of 1 (depth in baselines; the shape does not depend on the scale).

    python demos/cloud_figure.py EVAL SCENE_DIR --out docs/img/clouds.png
"""
import argparse
from pathlib import Path

import numpy as np

from lss_kernels import io
from lss_kernels.calib import Calibration
from lss_kernels.cloud import cloud
from lss_kernels.flying import flying_pixels
from lss_kernels.metrics import evaluation_masks

LABELS = {"lss": "lss_kernels", "sgm": "OpenCV SGBM + left-right check"}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("eval_dir")
    parser.add_argument("scene_dir")
    parser.add_argument("--out", required=True, help="PNG to write")
    parser.add_argument("--margin", type=int, default=30, help="pixels around the object")
    parser.add_argument("--view", type=float, nargs=2, default=(-70.0, -80.0),
                        metavar=("ELEV", "AZIM"), help="matplotlib's view angles")
    args = parser.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = io.load_scene(args.scene_dir)
    H, W = scene.left.shape[:2]
    ys, xs = np.nonzero(scene.fg_left)
    box = np.zeros((H, W), bool)
    box[max(ys.min() - args.margin, 0):ys.max() + args.margin + 1,
        max(xs.min() - args.margin, 0):xs.max() + args.margin + 1] = True
    band = evaluation_masks(scene)["band"]
    calib = Calibration(focal=float(W), baseline=1.0)
    runs = Path(args.eval_dir) / "runs" / scene.name
    truth, _ = calib.points(np.where(np.isfinite(scene.disp_left), scene.disp_left, 0.0), box)
    low, high = np.percentile(truth, 0.5, axis=0), np.percentile(truth, 99.5, axis=0)
    pad = 0.05 * (high - low)
    fig = plt.figure(figsize=(10, 4.6), dpi=110)
    for i, method in enumerate(("lss", "sgm")):
        disparity = io.read_pfm(runs / method / "disparity.pfm")
        occlusion = io.read_mask(runs / method / "occlusion.png")
        keep = box & ~occlusion
        layer = scene.fg_left.astype(np.uint8)
        points = cloud(calib, disparity, scene.left, layer, keep)
        _, kept = calib.points(disparity, keep)
        flying = flying_pixels(disparity, kept & band & np.isfinite(scene.disp_left),
                               scene.disp_left, scene.fg_left)[kept]
        share = 100.0 * flying.sum() / max(int((kept & band).sum()), 1)
        inside = ((points["xyz"] >= low - pad) & (points["xyz"] <= high + pad)).all(axis=1)
        xyz, rgb, flying = points["xyz"][inside], points["rgb"][inside] / 255.0, flying[inside]
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        ax.scatter(xyz[~flying, 0], xyz[~flying, 2], -xyz[~flying, 1], c=rgb[~flying], s=0.3,
                   depthshade=False, linewidths=0)
        ax.scatter(xyz[flying, 0], xyz[flying, 2], -xyz[flying, 1], c="red", s=1.2,
                   depthshade=False, linewidths=0)
        ax.set_xlim(low[0] - pad[0], high[0] + pad[0])
        ax.set_ylim(low[2] - pad[2], high[2] + pad[2])
        ax.set_zlim(-high[1] - pad[1], -low[1] + pad[1])
        ax.view_init(elev=args.view[0], azim=args.view[1])
        ax.set_title(f"{LABELS[method]}\nflying: {share:.1f} % of the band's points (red)",
                     fontsize=9)
        ax.set_xlabel("x")
        ax.set_ylabel("depth")
        ax.set_zlabel("-y")
        ax.tick_params(labelsize=6)
    fig.suptitle(f"{scene.name}: the object and the wall beside it", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
