"""One stereo pair solved into an output folder: what ``lss solve`` does for one pair and
``lss batch`` for each of many.

A :class:`Job` names the pair and how to start; :func:`run_job` solves it (reusing a cached
solver of the same image size and search range, :class:`SolverCache`) and writes the folder
with :func:`write_outputs`::

    disparity.pfm    left-view disparity (float32 PFM)
    confidence.pfm   how sure each pixel's disparity is, in [0, 1] (lss_kernels.confidence)
    confidence.png   the same as a picture (white: sure, black: occluded or unsure)
    occlusion.png    left-view occlusion mask (255 = seen by the left camera only)
    foreground.png   left-view foreground mask
    disparity.png    colour map with occlusions in dark blue and a colour bar
    overlay.png      boundary and occlusions over the left image
    summary.json     iterations, stop reason, seconds, Theta_1, Theta_2, parameters, the
                     score when the pair has ground truth

and with a calibration (:class:`lss_kernels.calib.Calibration`)::

    depth.pfm        left-view depth f B / (d + doffs), the baseline's unit (inf: unknown)
    cloud.ply        every pixel seen by both cameras: x y z, red green blue, layer
                     (0 background, 1 the object), confidence; binary little-endian
    object.ply       the object's pixels only

The folder is written to a temporary sibling and renamed into place, so a folder that exists
is complete.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import solver_cache

__all__ = ["Job", "SolverCache", "job_from_scene", "run_job", "scene_init", "sweep_summary",
           "write_outputs"]


@dataclass
class Job:
    """A pair to solve.

    Attributes
    ----------
    name : str
        The name of its output folder.
    left, right : array or path
        The rectified pair (left image = reference).
    d_max : float
        Largest disparity to search, left-view pixels.
    init : tuple, array or str
        The initial foreground (see :class:`lss_kernels.Solver`).
    init_frame : {"left", "cyclopean"}
    scene : lss_kernels.io.Scene or None
        The scene with its ground truth, to score the result (None: no score).
    photo : bool
        A whole photo: the object solved in a window around the start
        (:mod:`lss_kernels.photo`; ``init`` in the left view).
    """

    name: str
    left: Any
    right: Any
    d_max: float
    init: Any
    init_frame: str = "left"
    scene: Any = None
    photo: bool = False


def scene_init(scene, init=None):
    """``(init, frame)`` of a scene: ``init`` when given (left view), else the folder's
    ellipse (cyclopean when it gives one), else its click (``init_point``, a
    :class:`~lss_kernels.model.init.Point`), else ``"auto"``."""
    from ..start_types import Point
    if init is not None:
        return init, "left"
    if scene.init_ellipse_cyclopean is not None:
        return tuple(scene.init_ellipse_cyclopean), "cyclopean"
    if scene.init_ellipse is not None:
        return tuple(scene.init_ellipse), "left"
    if scene.init_point is not None:
        return Point(*scene.init_point), "left"
    return "auto", "left"


def job_from_scene(scene, d_max=None, init=None):
    """The :class:`Job` of a scene (:class:`lss_kernels.io.Scene`, or a folder): its own
    initial ellipse (cyclopean when the folder gives one) unless ``init`` is given."""
    from .. import io
    if not isinstance(scene, io.Scene):
        scene = io.load_scene(scene)
    d_max = float(scene.d_max if d_max is None else d_max)
    init, frame = scene_init(scene, init)
    has_truth = scene.disp_left is not None and scene.occ_left is not None
    return Job(scene.name, scene.left, scene.right, d_max, init, frame,
               scene if has_truth else None)


class SolverCache(solver_cache.SolverCache):
    """Keeps the last solver for the next job of the same image size, search range and
    parameters (:meth:`lss_kernels.Solver.reset`: no kernels to load again), and closes it
    when another one is needed (:class:`lss_kernels.solver_cache.SolverCache`)."""

    def solve(self, job, params, callback=None):
        """Solve ``job`` (solved again when the model collapses, :mod:`lss_kernels.checks.recovery`;
        in windows of a whole photo, :mod:`lss_kernels.photo`, for ``job.photo``); returns
        ``(result, facts)``: the left image, the initial foreground (left view) and the
        initialisation's report of the run kept."""
        if job.photo:
            from ..photo import solve_photo_cached
            if job.init_frame != "left":
                raise ValueError("init: a whole photo's start is given in the left view")
            return solve_photo_cached(self, job.left, job.right, job.d_max, job.init, params,
                                      callback)
        return self.solve_pair(job.left, job.right, job.d_max, job.init, job.init_frame,
                               params, callback)


def run_job(job, out_dir, params, cache=None, callback=None, extra=None, calib=None):
    """Solve ``job`` and write its folder ``out_dir``; returns the summary (the content of
    ``summary.json``).  ``cache``: a :class:`SolverCache` to reuse (else a solver of its own,
    closed before returning); ``callback(solver, stats)`` after every iteration; ``calib``:
    a :class:`~lss_kernels.calib.Calibration` for the metric outputs."""
    from ..kernels import backend
    own = cache is None
    cache = SolverCache() if own else cache
    start = time.perf_counter()
    try:
        result, (left, initial, init_info) = cache.solve(job, params, callback)
    finally:
        if own:
            cache.close()
    info = {"name": job.name, "wall_seconds": round(time.perf_counter() - start, 3),
            "d_max": float(job.d_max), "arch": backend.current_arch(),
            "init": _jsonable(init_info), "recovery": _jsonable(result.recovery),
            "photometry": _jsonable(result.photometry), "search": _jsonable(result.search)}
    if job.scene is not None:
        from ..metrics import score
        info["score"] = {k: (float(v) if hasattr(v, "__float__") else v)
                         for k, v in score(result.disparity, result.occlusion, job.scene).items()}
        info["score"]["bad4_surface"] = float(
            score(result.surface, result.occlusion, job.scene)["bad4"])
    info.update(extra or {})
    return write_outputs(out_dir, result, left, params, info, initial, calib)


def _jsonable(value):
    """Numbers, lists and dicts of ``value`` as plain Python (numpy scalars included)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def sweep_summary(history):
    """How often the background's plane sweep set Theta_2 (:mod:`lss_kernels.model.sweep`),
    and its last plane (iteration, left-view disparity)."""
    planes = [(s["iteration"], s["background_plane"]) for s in history
              if s.get("background_plane") is not None]
    last = (None if not planes else
            dict(iteration=planes[-1][0], disparity=round(float(planes[-1][1]), 3)))
    return dict(planes_set=len(planes), last=last)


def layer_summary(result):
    """What each value of ``layers.png`` is, with its surface, and the window solved."""
    from ..model.layers import BACKGROUND, FRONT, OBJECT
    from ..photo import OUTSIDE
    layers = {str(BACKGROUND): "behind the object: theta_bg",
              str(OBJECT): "the object (foreground.png): theta_fg"}
    if result.layers is not None and (result.layers == FRONT).any():
        layers[str(FRONT)] = ("in front of the object: its own matches (disparity.pfm), "
                              "no surface model")
    if result.window is not None:
        layers[str(OUTSIDE)] = "outside the window solved"
    return dict(values=layers, pixels={str(k): int(v) for k, v in zip(
        *np.unique(result.layers if result.layers is not None else
                   result.foreground.astype(np.uint8), return_counts=True))},
        window=None if result.window is None else list(result.window))


def _write_metric(folder, result, left, calib):
    """depth.pfm, cloud.ply and object.ply of ``result`` for ``calib``; returns their
    summary (the calibration and the clouds' point counts)."""
    from .. import io
    from ..cloud import cloud, select, write_ply
    io.write_pfm(os.path.join(folder, "depth.pfm"), result.depth(calib))
    layer = (result.layers if result.layers is not None
             else result.foreground.astype(np.uint8))
    counts = {}
    for name, which in (("cloud.ply", "all"), ("object.ply", "object")):
        points = cloud(calib, result.disparity, left, layer,
                       select(which, result.foreground, result.occlusion), result.confidence)
        write_ply(os.path.join(folder, name), points)
        counts[name] = int(len(points["xyz"]))
    cx, cy = calib.principal_point(result.disparity.shape)
    return dict(focal=calib.focal, baseline=calib.baseline, cx=cx, cy=cy, doffs=calib.doffs,
                points=counts)


def write_outputs(out_dir, result, left, params, extra=None, initial=None, calib=None):
    """Write the result files into ``out_dir`` atomically (a temporary sibling folder, then
    renamed into place); returns the summary.  ``initial``: the initial foreground (left
    view), drawn on ``overlay.png``; ``calib``: a calibration for depth.pfm and the
    clouds."""
    from .. import io, viz
    from ..params import REFINE_RATIO, REFINE_SUPPORT
    out_dir = os.fspath(out_dir)
    parent = os.path.dirname(os.path.abspath(out_dir)) or "."
    os.makedirs(parent, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=".lss-", dir=parent)
    try:
        io.write_pfm(os.path.join(tmp, "disparity.pfm"), result.disparity)
        io.write_pfm(os.path.join(tmp, "surface.pfm"), result.surface)
        io.write_pfm(os.path.join(tmp, "confidence.pfm"), result.confidence)
        io.write_png(os.path.join(tmp, "confidence.png"),
                     np.round(np.clip(result.confidence, 0, 1) * 255).astype(np.uint8))
        io.write_mask(os.path.join(tmp, "occlusion.png"), result.occlusion)
        io.write_mask(os.path.join(tmp, "foreground.png"), result.foreground)
        layers = (result.layers if result.layers is not None
                  else result.foreground.astype(np.uint8))
        io.write_png(os.path.join(tmp, "layers.png"), layers.astype(np.uint8))
        viz.save_layers_png(os.path.join(tmp, "layers_overlay.png"), left, layers)
        viz.save_disparity_png(os.path.join(tmp, "disparity.png"), result.disparity,
                               vmin=0.0, occlusion=result.occlusion)
        viz.save_overlay_png(os.path.join(tmp, "overlay.png"), left, result.foreground,
                             result.occlusion, initial)
        summary = dict(iterations=result.iterations, stop_reason=result.stop_reason,
                       seconds=round(result.timings.get("total", 0.0), 3),
                       timings={k: round(v, 4) for k, v in result.timings.items()},
                       theta_fg=np.round(result.theta_fg, 10).tolist(),
                       theta_bg=np.round(result.theta_bg, 10).tolist(),
                       theta_basis="left-view disparity over {x^2, xy, y^2, x, y, 1}, raw "
                                   "cyclopean pixel coordinates",
                       refinement=dict(enabled=params.refine,
                                       passes=[list(p) for p in params.refine_passes],
                                       ratio=REFINE_RATIO, support=REFINE_SUPPORT,
                                       seconds=round(result.timings.get("refine", 0.0), 4)),
                       background_sweep=sweep_summary(result.history),
                       layers=layer_summary(result),
                       params=params.to_dict())
        if calib is not None:
            summary["calibration"] = _write_metric(tmp, result, left, calib)
        summary.update(extra or {})
        with open(os.path.join(tmp, "summary.json"), "w") as f:
            json.dump(summary, f, indent=1)
        if os.path.isdir(out_dir):
            shutil.rmtree(out_dir)
        os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return summary
