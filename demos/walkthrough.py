"""A guided walk-through of two-layer level-set stereo, stage by stage, through the Python API.

Run from the repository root::

    python demos/walkthrough.py [--preset easy] [--out walkthrough] [--steps 40]
                                [--iterations 400] [--arch cpu]

It takes one built-in scene and saves one small PNG per stage into ``--out``, printing what
each shows:

1. the stereo pair and the initial boundary;
2. the matching-cost volume: one disparity slice and the cost curve at one pixel;
3. the patch messages (d_p, sigma_p) of one level along one scan line (Eq. 5);
4. the consensus: mean d-bar and confidence 1/sigma (Eq. 7);
5. the global shapes: the two quadratic surfaces Theta_1, Theta_2 (Eq. 8) and D (Eq. 3);
6. the state after a few level-set steps (Eq. 2);
7. the final left-view outputs beside the ground truth, with the paper's scores.

Only the public API is used: ``Solver.step``, ``Solver.snapshot``, ``Solver.patch_curve``,
``Solver.result``, and ``Solver.cost_slice`` where the solver has it (else the slice is the
raw absolute-difference cost computed here with numpy, the paper's M before aggregation).
"""
from __future__ import annotations

import argparse
import os
import sys
import textwrap
import time

import numpy as np

from lss_kernels import viz
from lss_kernels.kernels import backend

WIDTH = 400      # pixels of every stage figure
FONT = 7


# ------------------------------------------------------------------------------- helpers

def _say(stage, title, text):
    print(f"\n[{stage}] {title}")
    print(textwrap.fill(" ".join(text.split()), width=92, initial_indent="    ",
                        subsequent_indent="    "))


def _panels(images, titles, caption, out, name, contours=None):
    """A row of image panels ``WIDTH`` pixels wide with titles and a caption; saved as PNG."""
    n = len(images)
    h, w = images[0].shape[:2]
    pw = WIDTH / n
    ph = pw * h / w
    title_px, caption_px = 14, 16 + 11 * max(1, len(textwrap.wrap(caption, 78)) - 1)
    fig_h = int(round(ph + title_px + caption_px))
    fig = viz.new_figure(WIDTH, fig_h)
    for i, (img, title) in enumerate(zip(images, titles)):
        ax = fig.add_axes((i / n, caption_px / fig_h, 1.0 / n, ph / fig_h))
        ax.imshow(img, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(title, fontsize=FONT, pad=2)
        for mask, color in (contours or {}).get(i, []):
            m = np.asarray(mask, np.float32)
            if m.min() != m.max():
                ax.contour(m, levels=[0.5], colors=[color], linewidths=0.8)
    fig.text(0.5, 2.0 / fig_h, "\n".join(textwrap.wrap(caption, 78)), ha="center",
             va="bottom", fontsize=FONT - 0.5)
    return viz.save_figure(fig, os.path.join(out, name), size=(fig_h, WIDTH))


def _to_cyclopean_row(disp_row):
    """Ground truth along one row moved to the cyclopean frame: the disparity d at cyclopean
    x solves d = disp_left(x + d / 2) (a few fixed-point steps; occlusions make it ambiguous,
    which is fine for a plot; starting from the largest disparity picks the nearer layer where
    both layers project to the same cyclopean ray)."""
    w = disp_row.size
    x = np.arange(w, dtype=np.float64)
    d = np.full(w, float(np.max(disp_row)))     # start high: the nearer layer wins
    for _ in range(6):
        xl = np.clip(np.round(x + d / 2).astype(int), 0, w - 1)
        d = disp_row[xl].astype(np.float64)
    return d


def _raw_cost_slice(left, right, c):
    """|L(x + c) - R(x - c)| averaged over colour: the paper's M at cyclopean disparity c
    (left-view d = 2c), before any aggregation; out-of-image samples are NaN."""
    h, w = left.shape[:2]
    out = np.full((h, w), np.nan, np.float32)
    x = np.arange(w)
    ok = (x + c < w) & (x - c >= 0)
    xs = x[ok]
    out[:, ok] = np.abs(left[:, xs + c] - right[:, xs - c]).mean(axis=2)
    return out


def _raw_cost_curve(left, right, x, y, c_max):
    return np.array([_raw_cost_slice(left[y:y + 1], right[y:y + 1], c)[0, x]
                     for c in range(1, c_max + 1)])


def _plot_figure(height_px):
    return viz.new_figure(WIDTH, height_px)


def _caption(fig, text, height_px):
    fig.text(0.5, 2.0 / height_px, "\n".join(textwrap.wrap(text, 78)), ha="center",
             va="bottom", fontsize=FONT - 0.5)


# ------------------------------------------------------------------------------- stages

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="easy", help="built-in scene (lss_kernels.scenes)")
    ap.add_argument("--out", default="walkthrough", help="folder for the figures")
    ap.add_argument("--steps", type=int, default=40, help="phi steps shown in stage 6")
    ap.add_argument("--iterations", type=int, default=400, help="cap for the final stage")
    ap.add_argument("--arch", default=backend.DEFAULT_ARCH, choices=backend.ARCHES)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    arch = backend.init(arch=args.arch)
    from lss_kernels import Params, Solver, metrics, scenes

    scene = scenes.make_scene(args.preset)
    left, right, d_max = scene.left, scene.right, float(scene.d_max)
    h, w = left.shape[:2]
    if getattr(scene, "init_ellipse_cyclopean", None) is not None:
        init, frame = tuple(scene.init_ellipse_cyclopean), "cyclopean"
    else:
        init, frame = tuple(scene.init_ellipse), "left"
    params = Params().replace(max_iterations=max(args.iterations, args.steps + 1))
    t0 = time.perf_counter()
    s = Solver(left, right, d_max, init, params=params, init_frame=frame)
    print(f"scene '{args.preset}': {w}x{h}, d_max {d_max:g} px, arch {arch}; "
          f"solver set up in {time.perf_counter() - t0:.1f} s")
    written = []
    gt = scene.disp_left
    c_max = int(np.ceil(d_max / 2))

    # 1. the pair and the initial boundary --------------------------------------------------
    cy = init[1]
    row = int(round(cy))
    s.step()                                   # one iteration: messages, consensus, Theta
    snap1 = s.snapshot()
    init_left = snap1["initial_foreground"]
    text = ("The left (reference) and right images of the built-in scene: a textured "
            "foreground layer in front of a textured background. Yellow: the initial "
            "boundary, an ellipse given by the user (here the scene's), shown in the left "
            "view. The method never sees the ground truth.")
    written.append(_panels([left, right], ["left image (reference)", "right image"],
                           "1. Stereo pair; yellow: initial boundary (left view).",
                           args.out, "stage1_pair.png",
                           contours={0: [(init_left, viz.INIT_BOUNDARY_RGB)]}))
    _say(1, "stereo pair and initial boundary", text)

    # 2. the cost volume ---------------------------------------------------------------------
    fg_true = np.asarray(scene.fg_left, bool)
    xs_fg = np.nonzero(fg_true[row])[0]
    xl = int(xs_fg[len(xs_fg) // 2]) if xs_fg.size else w // 2     # a foreground pixel
    d_true = float(gt[row, xl])
    xc = int(np.clip(round(xl - d_true / 2), 0, w - 1))              # its cyclopean x
    c_true = max(1, int(round(d_true / 2)))
    if hasattr(s, "cost_slice"):
        slice_img = np.asarray(s.cost_slice(c_true), np.float32)
        slice_note = "Solver.cost_slice"
    else:
        slice_img = _raw_cost_slice(left, right, c_true)
        slice_note = "raw |L(x+c) - R(x-c)| computed in numpy (no Solver.cost_slice)"
    curve0 = s.patch_curve(0, xc, row)
    raw_curve = _raw_cost_curve(left, right, xc, row, c_max)
    fig_h = 215
    fig = _plot_figure(fig_h)
    ax = fig.add_axes((0.01, 0.25, 0.42, 0.64))
    top = np.nanpercentile(slice_img, 99) if np.isfinite(slice_img).any() else 1.0
    slice_rgb = viz.colorize(slice_img, 0, top, "viridis")
    slice_rgb[~np.isfinite(slice_img)] = 255            # no right-view sample: white
    ax.imshow(slice_rgb, interpolation="nearest")
    ax.plot([xc], [row], "c+", markersize=7)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"M(x, y, c={c_true}) (cyclopean)", fontsize=FONT, pad=2)
    ax = fig.add_axes((0.55, 0.33, 0.43, 0.56))
    d_axis = np.asarray(curve0["d"])
    ax.plot(d_axis, raw_curve, color="0.6", linewidth=0.8, label="pixel |L-R|")
    ax.plot(d_axis, curve0["matching_cost"], color="k", linewidth=1.0,
            label=f"{params.patch_sizes[0]}x{params.patch_sizes[0]} patch mean")
    ax.axvline(d_true, color="tab:green", linestyle="--", linewidth=0.8, label="true d")
    ax.set_xlabel("d (left-view px)", fontsize=FONT, labelpad=1)
    ax.tick_params(labelsize=FONT - 1)
    ax.legend(fontsize=FONT - 1.5, loc="lower left")
    ax.set_title(f"cost curve at cyclopean ({xc}, {row})", fontsize=FONT, pad=2)
    _caption(fig, "2. Matching cost: a slice of the volume at the true foreground disparity "
             "(dark = good match; white: no right-view pixel) and the cost curve at one "
             "pixel (+).", fig_h)
    written.append(viz.save_figure(fig, os.path.join(args.out, "stage2_cost.png"),
                                   size=(fig_h, WIDTH)))
    _say(2, "cost volume", f"Left: the matching cost at cyclopean disparity c = {c_true} "
         f"(left-view d = {2 * c_true}), {slice_note}; the foreground, whose true disparity "
         f"this is, is dark (low cost). Right: the cost curve at one foreground pixel, "
         f"alone and averaged over the smallest patch: the single pixel is erratic, the "
         f"patch mean has its minimum near the true disparity {d_true:g}.")

    # 3. patch messages along one row --------------------------------------------------------
    level = len(params.patch_sizes) // 2
    size = params.patch_sizes[level]
    step = max(1, w // 60)
    xs = np.arange(0, w, step)
    curves = [s.patch_curve(level, int(x), row) for x in xs]
    d_p = np.array([c["d_p"] for c in curves])
    sig = np.array([c["sigma_p"] for c in curves])
    valid = np.array([c["valid"] for c in curves])
    gt_cyc = _to_cyclopean_row(np.asarray(gt[row]))
    fig_h = 225
    fig = _plot_figure(fig_h)
    ax = fig.add_axes((0.1, 0.30, 0.78, 0.58))
    ax.plot(np.arange(w), gt_cyc, color="tab:green", linewidth=1.0, label="true d")
    ax.plot(xs[valid], d_p[valid], ".", color="tab:blue", markersize=3, label="$d_p$ (valid)")
    if (~valid).any():
        ax.plot(xs[~valid], d_p[~valid], "x", color="tab:red", markersize=3,
                label="$d_p$ (invalid)")
    ax2 = ax.twinx()
    ax2.plot(xs, sig, color="0.55", linewidth=0.8, label=r"$\sigma_p$ (right axis)")
    ax2.set_ylim(0, float(np.percentile(sig, 95)) * 1.3 + 1e-6)
    ax2.tick_params(labelsize=FONT - 1)
    ax2.set_ylabel(r"$\sigma_p$ (px)", fontsize=FONT, labelpad=1)
    ax.set_ylim(0, d_max * 1.05)
    ax.set_xlim(0, w - 1)
    ax.set_xlabel("cyclopean x", fontsize=FONT, labelpad=1)
    ax.set_ylabel("d (left-view px)", fontsize=FONT)
    ax.tick_params(labelsize=FONT - 1)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=FONT - 1.5,
              loc="lower center", ncol=4, framealpha=0.8)
    ax.set_title(f"patch messages, {size}x{size} patches, row y = {row}, iteration 1",
                 fontsize=FONT, pad=2)
    _caption(fig, "3. Each patch's message: the argmin of its cost, d_p, and a width "
             "sigma_p from the cost's contrast (Eq. 5); cyclopean frame.", fig_h)
    written.append(viz.save_figure(fig, os.path.join(args.out, "stage3_messages.png"),
                                   size=(fig_h, WIDTH)))
    _say(3, "patch messages", f"Every pixel centres one patch per level. Along row {row}, "
         f"the {size}x{size} patches' messages d_p (the argmin of the patch cost C_p) with "
         f"sigma_p = d_max / (mean C_p - min C_p) (grey, right axis): inside each layer d_p "
         f"follows the true disparity (green, moved to the cyclopean frame); patches that "
         f"straddle the boundary vote for one layer or a wrong value in between, and where "
         f"the cost has little contrast sigma_p grows. At iteration 1 all patches are valid "
         f"and C_p has no |d - D| term.")

    # 4. consensus -----------------------------------------------------------------------------
    mean, sigma = snap1["consensus_mean"], snap1["consensus_sigma"]
    inv = 1.0 / np.maximum(sigma, 1e-6)
    inv_top = float(np.percentile(inv, 99))
    written.append(_panels(
        [viz.colorize(mean, 0, d_max), viz.colorize(inv, 0, inv_top, "magma")],
        [r"consensus mean $\bar d$", f"confidence 1/σ (0–{inv_top:.2g})"],
        "4. Consensus after iteration 1 (cyclopean frame; d in left-view px, colour 0–"
        f"{d_max:g}).", args.out, "stage4_consensus.png"))
    _say(4, "consensus", "Every pixel multiplies the Gaussians of all valid patches that "
         "contain it (Eq. 7): the mean d-bar (left) and the confidence 1/sigma (right, "
         "bright = confident). Where the means are wrong (the boundary, texture-poor "
         "spots) the confidence is low, so these pixels weigh little in the fit of stage 5. "
         "Both maps are in the cyclopean frame.")

    # 5. global shapes -------------------------------------------------------------------------
    res1 = s.result()
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    basis = np.stack([xx * xx, xx * yy, yy * yy, xx, yy, np.ones_like(xx)], axis=-1)
    th_fg = basis @ np.asarray(res1.theta_fg, np.float64)
    th_bg = basis @ np.asarray(res1.theta_bg, np.float64)
    D_cyc = snap1.get("D", np.where(snap1["phi"] > 0, th_fg, th_bg))
    written.append(_panels(
        [viz.colorize(th_fg, 0, d_max), viz.colorize(th_bg, 0, d_max),
         viz.colorize(D_cyc, 0, d_max)],
        [r"$\Theta_1$ (foreground)", r"$\Theta_2$ (background)", "D (Eq. 3)"],
        "5. Global shapes fitted to the consensus (Eq. 8) after iteration 1; D picks Θ1 "
        "where φ > 0 (red). Cyclopean frame.", args.out, "stage5_shapes.png",
        contours={2: [(snap1["phi"] > 0, viz.BOUNDARY_RGB)]}))
    _say(5, "global shapes", "Theta_1 is a quadratic surface fitted by weighted least "
         "squares to the consensus means inside the current boundary, Theta_2 to those of "
         "the visible background (Eq. 8); confident pixels dominate. D takes Theta_1 where "
         "phi > 0 and Theta_2 elsewhere (Eq. 3). Red: the current boundary. When the "
         "initial boundary is too small, confident foreground pixels fall in the background "
         "region and bend Theta_2 upwards in the middle; the mismatch between Theta_2 and "
         "the matching cost there is what pushes the boundary outwards in the next steps.")

    # 6. after N phi steps -----------------------------------------------------------------
    while s.iteration < args.steps and not s.done:
        s.step()
    snap = s.snapshot()
    written.append(_panels(
        [left, viz.occlusion_disparity_rgb(snap["disparity"], snap["occlusion"], 0, d_max)],
        ["left; initial (yellow), now (red)", "D (left view); occluded: dark blue"],
        f"6. After {s.iteration} iterations of the alternation (Eq. 2 steps of φ between "
        "the updates of stages 3–5).", args.out, "stage6_evolving.png",
        contours={0: [(init_left, viz.INIT_BOUNDARY_RGB),
                      (snap["foreground"], viz.BOUNDARY_RGB)]}))
    _say(6, f"after {s.iteration} iterations", "Each iteration re-runs stages 3-5 with the "
         "current D as a prior (the beta |d - D| term) and patch validity from the current "
         "boundary and occlusion geometry, then moves phi by Eq. 2: the matching cost of "
         "the two surfaces, the occlusion-aware background term and the weighted "
         "curvature. The boundary (red) moves from the initial ellipse (yellow) towards the "
         "true outline; D is shown in the left view, where occlusions (dark blue) appear "
         "beside the foreground.")

    # 7. final vs ground truth -------------------------------------------------------------
    while not s.done:
        s.step()
    res = s.result()
    scores = metrics.score(res.disparity, res.occlusion, scene)
    gt_rgb = viz.occlusion_disparity_rgb(gt, getattr(scene, "occ_left", None), 0, d_max)
    est_rgb = viz.occlusion_disparity_rgb(res.disparity, res.occlusion, 0, d_max)
    written.append(_panels(
        [gt_rgb, est_rgb],
        ["truth; initial (yellow), final (red)", "final D; occluded: dark blue"],
        f"7. Final ({res.iterations} iterations): occlusion F1 {scores['occ_f1']:.2f}, "
        f"bad-4.0 {scores['bad4']:.1f}% (left view).", args.out, "stage7_final.png",
        contours={0: [(init_left, viz.INIT_BOUNDARY_RGB),
                      (res.foreground, viz.BOUNDARY_RGB)]}))
    _say(7, "final result vs ground truth", f"Stopped after {res.iterations} iterations "
         f"({res.stop_reason}). Left: the true disparity and occlusions with the initial "
         f"(yellow) and final (red) boundaries, like the paper's Fig. 3; right: the final D "
         f"with its occlusions. Occlusion F1 {scores['occ_f1']:.3f} and bad-4.0 "
         f"{scores['bad4']:.1f}% in the +-20 px band around the true boundary (the paper's "
         f"protocol, lss_kernels.metrics).")

    total = sum(os.path.getsize(p) for p in written)
    print(f"\nwrote {len(written)} PNGs ({total / 1024:.0f} KB) to {args.out} in "
          f"{time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
