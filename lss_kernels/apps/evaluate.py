"""Table 1 of the paper on a folder of scenes: run methods, score them, write tables and panels.

``lss eval DATASET_DIR`` runs every method on every scene folder of ``DATASET_DIR``, scores each
run with the paper's protocol (:func:`lss_kernels.metrics.score`) and writes, under ``--out``::

    runs/<scene>/<method>/disparity.pfm   left-view disparity (float32 PFM)
    runs/<scene>/<method>/occlusion.png   left-view occlusion mask (255 = occluded)
    runs/<scene>/lss/confidence.pfm       lss's per-pixel confidence (lss_kernels.confidence)
    runs/<scene>/<method>/result.json     the score and the seconds of the run
    results.csv                           one row per scene and method, then a mean per method
    table.md                              occlusion F1 per scene and method beside the paper's
    panels/<scene>.png                    left image, true and estimated disparities
    convergence.csv / .md / .png          with ``trace``: lss's two quadratics (unrefined)
                                          scored at every stop window, and variants of the
                                          stopping rule replayed

A run whose ``result.json`` exists is not repeated (the evaluation can be interrupted and
resumed) unless ``force`` is set.  ``results.csv``, ``table.md`` and the panels describe the
methods of the latest call (a panel is redrawn when one of its runs was recomputed or it is
missing).  Methods: ``lss`` (this package's solver, initialised with the
scene's cyclopean ellipse when it has one, the authors' own initialisation, else its left-view
ellipse), ``lss-photo`` (the scene as a whole photo, :mod:`lss_kernels.photo`, from the same
start in the left view) and the OpenCV peers of :mod:`lss_kernels.apps.baselines` (``sgm``, ``bm-lr``).
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from .. import io, metrics
from ..flying import flying_share
from .baselines import METHODS as BASELINES, require_opencv
from ..params import c_max
from ..stopping import StopRule
from . import reports
from .reports import COLUMNS

__all__ = ["COLUMNS", "METHOD_NAMES", "add_cli", "main_eval", "run_eval"]

#: Every method ``run_eval`` knows, in table order.
METHOD_NAMES = ("lss", "lss-photo") + tuple(BASELINES)


# ---------------------------------------------------------------------------------------------
# One run (executed on a Dask worker, or in the caller's process when jobs == 1)
# ---------------------------------------------------------------------------------------------

def _init_worker(arch: str, threads: int | None, methods) -> None:
    """Per-process set-up: Taichi for the solver, OpenCV's thread count for the peers (a
    no-op when done before with the same settings)."""
    if any(m.startswith("lss") for m in methods):
        from ..kernels import backend
        backend.init(arch=arch, threads=threads)
    if any(m in BASELINES for m in methods):
        require_opencv().setNumThreads(threads or os.cpu_count() or 1)


def _run_on_worker(task, methods, arch: str, threads_by_host: dict) -> dict:
    """:func:`_run_one` on a Dask worker, set up for ``methods`` first (Taichi starts once
    per worker process; its solver is kept for the next scene of the same size)."""
    from .batch import threads_here
    _init_worker(arch, threads_here(threads_by_host), methods)
    return _run_one(*task)


#: This process's last solver, reused (``Solver.reset``) for the next scene of the same size
#: and search range: a new Solver compiles its kernels again, which takes longer than many
#: scenes' iterations.
_SOLVER = {}


def scene_start(scene: io.Scene, init=None):
    """``(init, frame)`` for a scene: its own ellipse, else its click, else ``auto``
    (:func:`~lss_kernels.apps.jobs.scene_init`) when ``init`` is None; ``"auto"``;
    ``"gt-point"`` / ``"gt-box"``: a point at the centroid / the bounding box of the
    ground-truth foreground (a click, a detector), to measure those starts."""
    from ..start_types import Box, Point
    from .jobs import scene_init
    if init in ("gt-point", "gt-box"):
        if scene.fg_left is None or not scene.fg_left.any():
            raise ValueError(f"--init {init}: scene {scene.name} has no fg_left.png")
        ys, xs = np.nonzero(scene.fg_left)
        if init == "gt-point":
            return Point(float(xs.mean()), float(ys.mean())), "left"
        return Box(float(xs.min()), float(ys.min()), float(xs.max()) + 1.0,
                   float(ys.max()) + 1.0), "left"
    return scene_init(scene, init)


def _solve(scene: io.Scene, pair, params, trace: bool = False):
    """Solve a scene's :class:`~lss_kernels.checks.pair.CheckedPair` with this process's
    solver (a new one, after the last is closed, finds the kernels compiled for its size:
    :func:`lss_kernels.kernels.backend.fresh_numbering`); with ``trace``, also score the
    left view at the end of every stop window and at the last iteration.  Returns the
    result, the trace rows and the seconds spent scoring them."""
    from ..solver import Solver
    key = (pair.left.shape[:2], c_max(pair.d_max), params)
    args = (pair, pair.right, pair.d_max, pair.init)
    solver = _SOLVER.get(key)
    if solver is None:
        _release_solver()
        solver = Solver(*args, params=params, init_frame=pair.init_frame)
        _SOLVER[key] = solver
    else:
        solver.reset(*args, init_frame=pair.init_frame)
    rows, spent = [], [0.0]
    masks = metrics.evaluation_masks(scene) if trace else None
    window_end = StopRule(solver.params).is_window_end

    def record(s, stats):
        if window_end(s.iteration) or s.done:
            start = time.perf_counter()
            disparity, occlusion, _ = s.left_view()
            score = metrics.score(disparity, occlusion, scene, masks)
            rows.append({"iteration": s.iteration, "boundary_shift": stats["boundary_shift"],
                         "surface_change": stats["surface_change"],
                         "fg_fraction": stats["fg_fraction"],
                         "occ_f1": float(score["occ_f1"]), "bad4": float(score["bad4"])})
            spent[0] += time.perf_counter() - start

    return solver.run(record if trace else None), rows, spent[0]


def _release_solver() -> None:
    for solver in _SOLVER.values():
        solver.close()
    _SOLVER.clear()


def _solver_key(task):
    """Sort key that puts the runs one solver can share next to each other: the scene's
    image size (from the PNG header) and search range."""
    scene_dir = Path(task[0])
    try:
        meta = json.loads((scene_dir / "meta.json").read_text())
        shape = iio.improps(scene_dir / "left.png").shape[:2]
        return (0, tuple(shape), c_max(meta["d_max"]), str(scene_dir))
    except Exception:           # unreadable scenes fail later, with load_scene's message
        return (1, (), 0, str(scene_dir))


def _run_method(method: str, scene: io.Scene, params, trace: bool = False, init=None):
    """Disparity and occlusion (left view) of one method on one scene, extra facts, and the
    seconds spent on the trace."""
    if method == "lss":
        from ..start_types import InitError
        from ..checks.pair import CheckedPair
        from ..checks.recovery import named_warnings, with_recovery
        from .jobs import sweep_summary
        start, frame = scene_start(scene, init)
        pair = CheckedPair(scene.left, scene.right, scene.d_max, start, frame, params)

        def run(p):
            result, rows, spent = _solve(scene, pair, p, trace)
            return result, (rows, spent)
        try:
            with named_warnings(scene.name):
                result, (rows, spent) = with_recovery(run, params, pair.d_max, pair)
        except InitError as error:
            # no start found (auto, a point): the scene scores as no answer, the run goes on
            unknown = np.full(scene.left.shape[:2], np.inf, np.float32)
            extra = {"iterations": 0, "stop_reason": f"no start: {error}", "error": str(error),
                     "recovered": False, "periodic": False, "photometric": False,
                     "from_zero": False, "background_planes": 0,
                     "bad4_surface": 100.0}
            return unknown, np.zeros(unknown.shape, bool), extra, 0.0
        extra = {"iterations": int(result.iterations), "stop_reason": str(result.stop_reason),
                 "recovered": result.recovery.get("kept") == "retry",
                 "periodic": "first_params" in result.recovery,
                 "photometric": bool(result.photometry.get("correct")),
                 "from_zero": bool(result.search.get("from_zero")),
                 "background_planes": sweep_summary(result.history)["planes_set"],
                 "bad4_surface": float(metrics.score(result.surface, result.occlusion,
                                                     scene)["bad4"]),
                 "confidence": result.confidence}
        if trace:
            extra["trace"] = rows
        return result.disparity, result.occlusion, extra, spent
    if method == "lss-photo":
        return _run_photo(scene, params, init)
    disparity, occlusion = BASELINES[method](scene.left, scene.right, scene.d_max)
    return disparity, occlusion, {}, 0.0


def _run_photo(scene: io.Scene, params, init=None):
    """``lss-photo``: the scene as a whole photo (:func:`lss_kernels.photo.solve_photo`)
    from its start in the left view."""
    from ..photo import solve_photo
    from ..checks.recovery import named_warnings
    _release_solver()
    start, frame = scene_start(scene, init)
    if frame == "cyclopean":
        start = tuple(scene.init_ellipse)
    with named_warnings(scene.name):
        result = solve_photo(scene.left, scene.right, scene.d_max, start, params)
    windows = result.recovery.get("windows", [])
    extra = {"iterations": int(result.iterations), "stop_reason": str(result.stop_reason),
             "recovered": result.recovery.get("kept") == "retry", "windows": len(windows),
             "window": list(result.window),
             "bad4_surface": float(metrics.score(result.surface, result.occlusion,
                                                 scene)["bad4"])}
    return result.disparity, result.occlusion, extra, 0.0


def _run_one(scene_dir: str, method: str, run_dir: str, params, trace: bool = False,
             init=None) -> dict:
    """Run, score and save one (scene, method); return the record written to result.json
    (``seconds`` leaves out the scoring of a trace)."""
    scene = io.load_scene(scene_dir)
    start = time.perf_counter()
    disparity, occlusion, extra, spent = _run_method(method, scene, params, trace, init)
    seconds = time.perf_counter() - start - spent
    disparity = np.asarray(disparity, dtype=np.float32)
    occlusion = np.asarray(occlusion, dtype=bool)
    scores = {k: _plain(v) for k, v in metrics.score(disparity, occlusion, scene).items()}
    scores.update(flying_share(disparity, occlusion, scene))
    confidence = extra.pop("confidence", None)
    record = {"scene": Path(scene_dir).name, "method": method, **scores, "seconds": seconds,
              **extra}
    out = Path(run_dir)
    out.mkdir(parents=True, exist_ok=True)
    io.write_pfm(out / "disparity.pfm", disparity)
    io.write_mask(out / "occlusion.png", occlusion)
    if confidence is not None:
        io.write_pfm(out / "confidence.pfm", confidence)
    # result.json last: its presence means the run is complete.
    tmp = out / "result.json.tmp"
    tmp.write_text(json.dumps(record, indent=1))
    os.replace(tmp, out / "result.json")
    return record


def _plain(value):
    """numpy scalars to Python numbers, for JSON."""
    return value.item() if isinstance(value, np.generic) else value


# ---------------------------------------------------------------------------------------------
# The engine
# ---------------------------------------------------------------------------------------------

def _check_methods(methods) -> tuple:
    methods = tuple(methods)
    valid = ", ".join(METHOD_NAMES)
    if not methods:
        raise ValueError(f"no method given; valid: {valid}")
    unknown = [m for m in methods if m not in METHOD_NAMES]
    if unknown:
        raise ValueError(f"unknown method(s) {', '.join(map(repr, unknown))}; valid: {valid}")
    if any(m in BASELINES for m in methods):
        require_opencv()
    return tuple(dict.fromkeys(methods))


def run_eval(dataset_dir, methods=("lss", "sgm", "bm-lr"), out="eval_out", jobs: int = 1,
             force: bool = False, arch: str = "cpu", params=None,
             progress: bool = True, trace: bool = False, scheduler: str | None = None,
             init=None) -> list:
    """Run ``methods`` on every scene of ``dataset_dir``, score them and write the report.

    Parameters
    ----------
    dataset_dir : str or path-like
        A folder of scene folders (see ``docs/scene-format.md``); ``paper_table1.json`` in it, if
        present, adds the paper's numbers to ``table.md``.
    methods : sequence of str
        Any of :data:`METHOD_NAMES`.
    out : str or path-like
        Output folder (created).
    jobs : int
        Worker processes of a local Dask cluster (:func:`lss_kernels.apps.batch.dask_client`;
        needs Dask); each initialises Taichi once with ``max(1, cpu_count // jobs)`` threads.
        ``jobs=1`` runs in the calling process without Dask, initialising Taichi there with
        ``arch`` unless it already runs on ``arch``.
    force : bool
        Recompute runs that already have a ``result.json``.
    arch : str
        Taichi arch for ``lss`` (see :func:`lss_kernels.kernels.backend.init`).
    params : lss_kernels.Params or None
        Solver parameters for ``lss`` (``None``: ``Params()``, the recommended defaults).
    progress : bool
        Print one line per finished (scene, method) to stderr.
    trace : bool
        Also score ``lss`` at the end of every stop window (its ``result.json`` gets a
        ``trace``) and write ``convergence.csv``, ``convergence.md`` (accuracy against
        iterations, and where variants of the stopping rule would have stopped) and
        ``convergence.png``.  The scoring is left out of ``seconds``.
    scheduler : str or None
        Address of a running Dask scheduler: run there instead (``jobs`` is then unused).
    init : {None, "auto", "gt-point", "gt-box"}
        How ``lss`` starts (:func:`scene_start`); None: each scene's own ellipse or click.

    Returns
    -------
    list of dict
        One record per (scene, method), in scene then method order: ``scene``, ``method``, the
        keys of :func:`lss_kernels.metrics.score`, ``seconds`` (wall-clock of the method alone,
        without loading and scoring), for ``lss`` also ``iterations`` and ``stop_reason``, and
        ``skipped`` (True when read from an earlier run's ``result.json``).

    Raises
    ------
    ValueError
        Unknown method, ``jobs < 1``, or no scene folder in ``dataset_dir``.
    FileNotFoundError
        ``dataset_dir`` is not a folder.
    ImportError
        One line, when a requested peer needs OpenCV and it is missing, or ``jobs > 1`` or
        ``scheduler`` and Dask is missing.
    """
    methods = _check_methods(methods)
    if not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs: expected an integer >= 1, got {jobs!r}")
    remote = jobs > 1 or scheduler is not None
    if remote:
        from .batch import require_dask
        require_dask(f"--jobs {jobs}" if scheduler is None else "--scheduler")
    scene_dirs = [Path(p) for p in io.list_scenes(dataset_dir)]
    out = Path(out)
    names = [p.name for p in scene_dirs]

    records, todo = {}, []
    for scene_dir in scene_dirs:
        for method in methods:
            run_dir = out / "runs" / scene_dir.name / method
            done = run_dir / "result.json"
            if done.exists() and not force:
                records[scene_dir.name, method] = {**json.loads(done.read_text()),
                                                   "skipped": True}
            else:
                todo.append((os.fspath(scene_dir), method, os.fspath(run_dir), params,
                             trace and method == "lss", init))

    total = len(names) * len(methods)
    log = _Progress(total, enabled=progress)
    for record in records.values():
        log.done(record)
    fresh = {}
    run = (_execute_on_dask(todo, methods, jobs, arch, scheduler) if remote
           else _execute(todo, methods, arch))
    for record in run:
        record["skipped"] = False
        fresh[record["scene"], record["method"]] = record
        log.done(record)
    records.update(fresh)

    rows = [records[n, m] for n in names for m in methods]
    reports.write_csv(out / "results.csv", rows, methods)
    reports.write_table(out / "table.md", rows, names, methods, Path(dataset_dir))
    for scene_dir in scene_dirs:
        panel = out / "panels" / f"{scene_dir.name}.png"
        if any((scene_dir.name, m) in fresh for m in methods) or not panel.exists():
            reports.write_panel(panel, scene_dir, [records[scene_dir.name, m] for m in methods], out)
    traced = [r for r in rows if r["method"] == "lss" and r.get("trace")]
    if trace and "lss" in methods:
        missing = [r["scene"] for r in rows if r["method"] == "lss" and not r.get("trace")]
        if missing and progress:
            print(f"lss eval: {len(missing)} lss run(s) finished earlier without --trace are "
                  f"left out of convergence.md (use --force to trace them)", file=sys.stderr)
        if traced:
            from ..params import Params
            reports.write_convergence(out, traced, params if params is not None else Params(),
                               missing)
    return rows


def _execute(todo, methods, arch: str):
    """Yield the records of the runs in ``todo``, run one after the other in this process."""
    if not todo:
        return
    if any(m.startswith("lss") for m in methods):
        from ..kernels import backend
        if backend.current_arch() != arch:
            backend.init(arch=arch)
    try:
        for task in sorted(todo, key=_solver_key):
            yield _run_one(*task)
    finally:
        _release_solver()


def _execute_on_dask(todo, methods, jobs: int, arch: str, scheduler: str | None):
    """Yield the records of the runs in ``todo`` as they finish on Dask: a local cluster of
    ``jobs`` worker processes, or the cluster at ``scheduler``."""
    if not todo:
        return
    from distributed import as_completed
    from .batch import cluster_arch, dask_client, worker_threads
    if any(m.startswith("lss") for m in methods):
        arch = cluster_arch(arch, scheduler)
    with dask_client(jobs, scheduler, what=f"--jobs {jobs}") as client:
        threads = worker_threads(client)
        futures = [client.submit(_run_on_worker, task, methods, arch, threads, pure=False)
                   for task in sorted(todo, key=_solver_key)]
        for future in as_completed(futures):
            yield future.result()


class _Progress:
    """One line per finished (scene, method): running count, scores and seconds."""

    def __init__(self, total: int, enabled: bool):
        self.total, self.count, self.enabled = total, 0, enabled

    def done(self, record: dict) -> None:
        self.count += 1
        if not self.enabled:
            return
        how = "cached" if record["skipped"] else f"{record['seconds']:.1f} s"
        print(f"[{self.count}/{self.total}] {record['scene']} {record['method']}: "
              f"F1 {record['occ_f1']:.2f}, bad-4.0 {record['bad4']:.1f} % ({how})",
              file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------

def add_cli(subparsers) -> None:
    """Register ``eval`` on an ``argparse`` sub-parsers object (handler: :func:`main_eval`)."""
    from ..kernels.backend import ARCHES, DEFAULT_ARCH
    p = subparsers.add_parser(
        "eval", help="run and score methods on a folder of scenes (the paper's Table 1)",
        description="Run each method on every scene folder of DATASET_DIR, score it with the "
                    "paper's protocol and write results.csv, table.md and panels/ to --out. "
                    "Finished runs are reused unless --force.")
    p.add_argument("dataset_dir", metavar="DATASET_DIR", help="folder of scene folders")
    p.add_argument("--methods", default=",".join(METHOD_NAMES),
                   help=f"comma-separated, any of {', '.join(METHOD_NAMES)} "
                        "(default: %(default)s)")
    p.add_argument("--out", default="eval_out", help="output folder (default: %(default)s)")
    p.add_argument("--jobs", type=int, default=1,
                   help="worker processes of a local Dask cluster (default: 1, no Dask)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on the Dask cluster at this scheduler address instead")
    p.add_argument("--force", action="store_true", help="recompute finished runs")
    p.add_argument("--arch", default=DEFAULT_ARCH, metavar="ARCH",
                   help=f"Taichi backend for lss: {', '.join(ARCHES)} (default {DEFAULT_ARCH}: "
                        f"CUDA if a device answers, else the CPU)")
    p.add_argument("--trace", action="store_true",
                   help="score lss's two quadratics (unrefined) at the end of every stop "
                        "window; writes convergence.csv, "
                        ".md (with variants of the stopping rule replayed) and .png")
    p.add_argument("--init", choices=("auto", "gt-point", "gt-box"),
                   help="start lss from auto, or from a point at the centroid / the bounding "
                        "box of the true foreground, instead of each scene's ellipse or "
                        "click (use its own --out)")
    p.add_argument("--params", choices=("default", "paper"), default="default",
                   help="lss's parameter set: default (recommended) or paper (the paper's "
                        "method and nothing beyond it, Params.paper; use its own --out)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter of that set (repeatable), e.g. --param "
                        "front_margin=4 (use its own --out)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=main_eval)


def main_eval(args) -> int:
    """Handler of ``lss eval``: 0 on success, 2 with a one-line message on a usage error
    (unknown method, missing OpenCV, no such folder, no scenes)."""
    from ..params import Params
    from .cli import CliError, param_changes
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    try:
        params = Params.paper() if args.params == "paper" else Params()
        changes = param_changes(args.param, params)
        params = params.replace(**changes) if changes else params
        if args.params == "default" and not changes:
            params = None                      # run_eval's default, Params()
    except (CliError, ValueError) as error:
        print(f"lss eval: error: {error}", file=sys.stderr)
        return 2
    try:
        rows = run_eval(args.dataset_dir, methods=methods, out=args.out, jobs=args.jobs,
                        force=args.force, arch=args.arch, params=params,
                        progress=not args.quiet, trace=args.trace, scheduler=args.scheduler,
                        init=args.init)
    except (ValueError, FileNotFoundError, ImportError) as error:
        print(f"lss eval: error: {error}", file=sys.stderr)
        return 2
    if not args.quiet:
        print(Path(args.out, "table.md").read_text(), end="")
        print(f"{len(rows)} runs; results in {args.out}", file=sys.stderr)
    return 0
