"""``lss demo``: watch the solver work, in the layout of the paper's Fig. 1.

The demo steps a :class:`~lss_kernels.Solver` and every ``every`` iterations records

* a frame laid out like Fig. 1(b): the left image with the current (red) and initial (yellow)
  boundary, the consensus mean d-bar and its confidence 1/sigma (Eq. 7, cyclopean frame), the
  two-surface disparity D (Eq. 3) with occlusions in dark blue, and, when ground truth exists,
  the true disparity with the current boundary; the caption gives the iteration and, with
  ground truth, the running occlusion F1 and bad-4.0;
* the disparity message of one patch, drawn as in Fig. 1(a) (Eq. 6).

Outputs under ``out``: ``frames/frame_0000.png ...``, ``evolution.gif`` (loops forever; one frame
per recorded iteration ``every, 2 every, ...`` and the final state last), ``patch.png`` (Fig. 1(a)),
the final ``disparity.png``, ``overlay.png`` and ``layers.png`` (the layer map over the left
image: behind the object grey, the object red, in front of it blue; left view, the input's
size; the layer in front of the object with ``Params.front_margin``, :mod:`lss_kernels.model.front`).

Command line (registered by :func:`add_cli`)::

    lss demo [--scene DIR | LEFT RIGHT --dmax N] [--init auto|point:X,Y|box:X0,Y0,X1,Y1|ellipse:CX,CY,RX,RY|MASK.png]
             [--preset NAME] [--out DIR] [--every K] [--arch ARCH] [--patch X,Y,LEVEL]
             [--iterations N] [--quiet]
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

from .. import viz
from ..stopping import format_shift
from . import figures

__all__ = ["run_demo", "add_cli", "main_demo", "parse_init", "parse_patch", "default_patch",
           "recorded_iterations"]

DEFAULT_PRESET = "easy"


# ---------------------------------------------------------------------------------------------
# Parsing
# ---------------------------------------------------------------------------------------------

def parse_init(text: str, shape=None):
    """Parse ``--init`` (``auto``, ``point:X,Y``, ``box:X0,Y0,X1,Y1``, ``ellipse:CX,CY,RX,RY``
    or a mask PNG; none = ``auto``) with :func:`lss_kernels.checks.validate.parse_init` and, given
    the image ``shape``, check it against the image with
    :func:`lss_kernels.checks.validate.check_init`."""
    from ..checks.validate import check_init, parse_init as parse
    init = "auto" if text is None else parse(text)
    return check_init(init, shape) if shape is not None else init


def parse_patch(text: str, n_levels: int | None = None):
    """Parse ``--patch X,Y,LEVEL`` (cyclopean pixels, level index) into ``(x, y, level)``."""
    parts = text.split(",")
    try:
        x, y, level = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"--patch: expected X,Y,LEVEL as three integers, got {text!r}") from None
    if x < 0 or y < 0 or level < 0 or (n_levels is not None and level >= n_levels):
        raise ValueError(f"--patch: expected X, Y >= 0 and 0 <= LEVEL < {n_levels}, got {text!r}")
    return x, y, level


def recorded_iterations(n_iterations: int, every: int) -> list:
    """The iterations at which :func:`run_demo` records a frame when the solver runs
    ``n_iterations`` steps: every, 2 every, ... and the last one.  (Iteration 0 is not
    recorded: the consensus and the messages exist only after the first step.)"""
    its = list(range(every, n_iterations + 1, every))
    if not its or its[-1] != n_iterations:
        its.append(n_iterations)
    return its


def default_patch(phi0: np.ndarray, n_levels: int, patch_sizes=None):
    """The default patch of :func:`run_demo`: middle level, on the row through the centre of
    the initial foreground (``phi > 0``, cyclopean frame), at its left boundary: the patch
    lies just inside, its left edge on the boundary (given ``patch_sizes``; else centred on
    the boundary pixel)."""
    fg = np.asarray(phi0) > 0
    level = n_levels // 2
    if not fg.any():
        h, w = fg.shape
        return w // 2, h // 2, level
    rows, _ = np.nonzero(fg)
    y = int(round(rows.mean()))
    cols = np.nonzero(fg[y])[0]
    if cols.size == 0:
        y = int(rows[np.argmin(np.abs(rows - y))])
        cols = np.nonzero(fg[y])[0]
    half = int(patch_sizes[level]) // 2 if patch_sizes is not None else 0
    x = min(int(cols.min()) + half, int(cols.max()))
    return x, y, level


# ---------------------------------------------------------------------------------------------
# The demo
# ---------------------------------------------------------------------------------------------

def _scores(snapshot, scene):
    if scene is None or getattr(scene, "disp_left", None) is None:
        return None
    from .. import metrics
    return metrics.score(snapshot["disparity"], snapshot["occlusion"], scene)


def run_demo(left, right, d_max, init, out, every=10, max_iterations=None, patch=None,
             scene=None, init_frame="left", progress=True, params=None, arch=None) -> dict:
    """Run the solver and record its evolution like the paper's Fig. 1.

    Parameters
    ----------
    left, right : (H, W, 3) float32 in [0, 1]
        Rectified pair; the left image is the reference.
    d_max : float
        Largest disparity (left-view pixels).
    init : (cx, cy, rx, ry) or (H, W) bool
        Initial foreground (ellipse or mask) in the frame ``init_frame``.
    out : str or path-like
        Output folder (created).
    every : int
        Record a frame every this many iterations (and after the last one).
    max_iterations : int or None
        Iteration cap (``None``: ``params.max_iterations``).
    patch : (x, y, level) or None
        Patch of Fig. 1(a) (cyclopean pixels, level index into ``params.patch_sizes``);
        ``None``: :func:`default_patch`.
    scene : Scene or None
        Ground truth (``disp_left``, ...) for the last panel and the running scores.
    init_frame : {"left", "cyclopean"}
    progress : bool
        Print one line per recorded iteration and a summary.
    params : Params or None
    arch : str or None
        Passed to the solver (Taichi must already be initialised; see :mod:`lss_kernels.kernels.backend`).

    Returns
    -------
    dict
        ``frames`` (list of PNG paths), ``gif``, ``patch``, ``disparity``, ``overlay``,
        ``layers``.
    """
    import imageio.v3 as iio

    from .. import Params, Solver

    every = int(every)
    if every < 1:
        raise ValueError(f"every: expected an integer >= 1, got {every!r}")
    params = params if params is not None else Params()
    if max_iterations is not None:
        params = params.replace(max_iterations=int(max_iterations))
    out = os.fspath(out)
    frames_dir = os.path.join(out, "frames")
    os.makedirs(frames_dir, exist_ok=True)
    for name in os.listdir(frames_dir):        # frames of an earlier run would be mixed in
        if name.startswith("frame_") and name.endswith(".png"):
            os.remove(os.path.join(frames_dir, name))

    left = np.asarray(left, np.float32)
    t0 = time.perf_counter()
    solver = Solver(left, right, d_max, init, params=params, arch=arch, init_frame=init_frame)
    n_levels = len(solver.params.patch_sizes)
    phi0 = solver.result().phi          # the initial phi (cyclopean), before any step
    if patch is None:
        patch = default_patch(phi0, n_levels, solver.params.patch_sizes)
    px, py, plevel = (int(v) for v in patch)
    h, w = phi0.shape
    if not (0 <= px < w and 0 <= py < h and 0 <= plevel < n_levels):
        raise ValueError(f"patch: ({px}, {py}, {plevel}) is outside the {w}x{h} grid or the "
                         f"{n_levels} levels")
    true_disp = None if scene is None else getattr(scene, "disp_left", None)

    frames, frame_paths, curves = [], [], []
    last_info = {}
    snap = None

    def record(snapshot):
        it = solver.iteration
        scores = _scores(snapshot, scene)
        frame = figures.evolution_frame(left, snapshot, d_max, it, true_disparity=true_disp,
                                    scores=scores)
        path = os.path.join(frames_dir, f"frame_{len(frame_paths):04d}.png")
        viz.save_rgb_png(path, frame)
        frames.append(frame)
        frame_paths.append(path)
        curves.append((it, solver.patch_curve(plevel, px, py)))
        if progress:
            line = f"iter {it:5d}"
            if last_info:
                line += (f"  flipped {last_info['flipped']:6d}  fg {last_info['fg_fraction']:.3f}"
                         f"  shift {format_shift(last_info['boundary_shift'])}"
                         f"  step {1e3 * last_info['seconds']:7.1f} ms")
            if scores:
                line += (f"  occ F1 {float(scores['occ_f1']):.3f}"
                         f"  bad-4.0 {float(scores['bad4']):.1f}%")
            print(line, flush=True)

    recorded = set()
    while not solver.done and solver.iteration < params.max_iterations:
        last_info = solver.step()
        if solver.iteration % every == 0:
            snap = solver.snapshot()
            record(snap)
            recorded.add(solver.iteration)
    if solver.iteration not in recorded:
        snap = solver.snapshot()
        record(snap)

    gif_path = os.path.join(out, "evolution.gif")
    durations = [250] * (len(frames) - 1) + [1500]
    iio.imwrite(gif_path, np.stack(frames), extension=".gif", duration=durations, loop=0)

    result = solver.result()
    patch_size = solver.params.patch_sizes[plevel]
    last_curve = curves[-1][1]
    shift = float(last_curve.get("mean_D", 0.0)) / 2.0 if np.isfinite(
        last_curve.get("mean_D", np.nan)) else 0.0
    shown = max(patch_size, w // 40)     # a tiny patch on a large image: outline it larger
    box = (px + shift - shown // 2, py - shown // 2, shown)
    fig = figures.patch_message_figure(
        curves, left=left, patch_box=box,
        title=(f"disparity message of the {patch_size}x{patch_size} patch at cyclopean "
               f"({px}, {py}), level {plevel} (Fig. 1a)"))
    patch_path = viz.save_figure(fig, os.path.join(out, "patch.png"))
    disp_path = viz.save_disparity_png(os.path.join(out, "disparity.png"), result.disparity,
                                       0, d_max, title="D (left view)",
                                       occlusion=result.occlusion)
    init_fg = snap.get("initial_foreground")
    overlay_path = viz.save_overlay_png(os.path.join(out, "overlay.png"), left,
                                        result.foreground, result.occlusion, init_fg)
    layers_path = viz.save_layers_png(os.path.join(out, "layers.png"), left, result.layers)
    if progress:
        print(f"{solver.iteration} iterations ({solver.stop_reason or 'cap'}) in "
              f"{time.perf_counter() - t0:.1f} s; wrote {len(frame_paths)} frames, "
              f"{gif_path}, {patch_path}, {disp_path}, {overlay_path}, {layers_path}",
              flush=True)
    return dict(frames=frame_paths, gif=gif_path, patch=patch_path, disparity=disp_path,
                overlay=overlay_path, layers=layers_path)


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------

def add_cli(subparsers):
    """Register the ``demo`` sub-command on an ``argparse`` sub-parsers object."""
    from ..kernels.backend import ARCHES, DEFAULT_ARCH
    p = subparsers.add_parser(
        "demo", help="watch the solver evolve (frames, GIF, a patch's message; paper Fig. 1)",
        description="Run the solver on a built-in scene, a scene folder or a stereo pair and "
                    "record its evolution in the layout of the paper's Fig. 1.")
    p.add_argument("images", nargs="*", metavar="LEFT RIGHT",
                   help="left and right image files (with --dmax)")
    p.add_argument("--scene", metavar="DIR", help="a scene folder (lss_kernels.io.load_scene)")
    p.add_argument("--preset", default=DEFAULT_PRESET, metavar="NAME",
                   help=f"built-in scene used without data arguments (default {DEFAULT_PRESET})")
    p.add_argument("--dmax", type=float, metavar="N", help="largest disparity (left-view px)")
    p.add_argument("--init", metavar="SPEC",
                   help="initial boundary (left view): auto, point:X,Y, box:X0,Y0,X1,Y1, "
                        "ellipse:CX,CY,RX,RY or a mask PNG (default: the scene's ellipse, "
                        "else auto)")
    p.add_argument("--out", default="lss_demo", metavar="DIR", help="output folder")
    p.add_argument("--every", type=int, default=10, metavar="K",
                   help="record a frame every K iterations (default 10)")
    p.add_argument("--arch", default=DEFAULT_ARCH, metavar="ARCH",
                   help=f"Taichi backend: {', '.join(ARCHES)} (default {DEFAULT_ARCH}: CUDA if a "
                        f"device answers, else the CPU)")
    p.add_argument("--patch", metavar="X,Y,LEVEL",
                   help="patch of the Fig. 1(a) plot (cyclopean pixels, level index)")
    p.add_argument("--iterations", type=int, metavar="N", help="iteration cap")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=main_demo)
    return p


def _fail(message: str) -> int:
    print(f"lss demo: error: {message}", file=sys.stderr)
    return 2


def main_demo(args) -> int:
    """Entry point of ``lss demo`` (``args`` from the parser of :func:`add_cli`)."""
    images = list(getattr(args, "images", []) or [])
    scene, init_frame = None, "left"
    try:
        if args.every is not None and args.every < 1:
            raise ValueError(f"--every: expected an integer >= 1, got {args.every}")
        if args.iterations is not None and args.iterations < 1:
            raise ValueError(f"--iterations: expected an integer >= 1, got {args.iterations}")
        patch = parse_patch(args.patch) if args.patch else None
        if images and args.scene:
            raise ValueError("give either --scene DIR or LEFT RIGHT, not both")
        if images:
            if len(images) != 2:
                raise ValueError(f"expected two images LEFT RIGHT, got {len(images)} argument(s)")
            if args.dmax is None or not np.isfinite(args.dmax) or args.dmax <= 0:
                raise ValueError("--dmax: a positive number is required with LEFT RIGHT")
            for path in images:
                if not os.path.isfile(path):
                    raise ValueError(f"no such image file: {path!r}")
            from ..io import read_image
            left, right = read_image(images[0], 'left'), read_image(images[1], 'right')
            if left.shape != right.shape:
                raise ValueError(f"the images differ in size: {left.shape[1]}x{left.shape[0]} "
                                 f"and {right.shape[1]}x{right.shape[0]}")
            init = parse_init(args.init, left.shape[:2])
            d_max = float(args.dmax)
        else:
            if args.scene:
                from .. import io
                if not os.path.isdir(args.scene):
                    raise ValueError(f"--scene: no such folder {args.scene!r}")
                scene = io.load_scene(args.scene)
            else:
                from .. import scenes
                scene = scenes.make_scene(args.preset)
            left, right = scene.left, scene.right
            d_max = float(args.dmax) if args.dmax is not None else float(scene.d_max)
            from .jobs import scene_init
            init, init_frame = scene_init(
                scene, parse_init(args.init, left.shape[:2]) if args.init else None)
    except (ValueError, KeyError, FileNotFoundError) as exc:
        return _fail(str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc))

    from ..kernels import backend
    arch = backend.init(arch=args.arch)
    if not args.quiet:
        print(f"lss demo: {left.shape[1]}x{left.shape[0]}, d_max {d_max:g}, arch {arch}, "
              f"output {args.out}", flush=True)
    try:
        run_demo(left, right, d_max, init, args.out, every=args.every,
                 max_iterations=args.iterations, patch=patch, scene=scene,
                 init_frame=init_frame, progress=not args.quiet)
    except ValueError as exc:
        return _fail(str(exc).strip().splitlines()[0])
    return 0
