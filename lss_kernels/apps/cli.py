"""``lss``: the command line.

``lss solve``   one stereo pair or scene folder -> left-view disparity, occlusion, foreground
``lss demo``    watch the cooperative dynamics (paper Fig. 1)
``lss eval``    Table 1 of the paper on a dataset, with classical peers
``lss bench``   stage-by-stage timings and scaling
``lss batch``   many pairs or scene folders on a Dask cluster

Errors on the command line are one line on stderr and exit status 2; nothing half-written is
left in ``--out`` (results are written to a temporary folder that is moved into place).
"""
import argparse
import importlib
import os
import sys
import warnings

if "--json" in sys.argv[1:]:
    # stdout carries one JSON object: no Taichi banner when backend imports Taichi
    os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

from .. import __version__  # noqa: E402
from ..kernels.backend import ARCHES, DEFAULT_ARCH  # noqa: E402
from ..stopping import format_shift  # noqa: E402

__all__ = ["main"]

#: The other commands and the modules that define them (``add_cli``), imported only when
#: their command runs or the full help is asked for: ``lss solve`` does not import the
#: pictures' matplotlib, OpenCV or Dask before it needs them.
SUBCOMMAND_MODULES = {"demo": "demo", "eval": "evaluate", "bench": "bench", "batch": "batch"}


class CliError(Exception):
    """A one-line error for the user."""


def _add_solve(subparsers):
    p = subparsers.add_parser(
        "solve", help="solve one pair or scene folder",
        description="Two-layer level-set stereo on a rectified pair (left image = reference). "
                    "Writes disparity.pfm, confidence.pfm, occlusion.png, foreground.png, "
                    "disparity.png, confidence.png, overlay.png and summary.json into --out; "
                    "with a calibration also depth.pfm, cloud.ply and object.ply.")
    p.add_argument("images", nargs="*", metavar="LEFT RIGHT", help="left and right images")
    p.add_argument("--scene", metavar="DIR", help="scene folder (reads d_max and, when given, "
                   "init_ellipse or else init_point from meta.json)")
    p.add_argument("--preset", metavar="NAME", help="a built-in rendered scene with ground "
                   "truth (easy, slanted, tiny) instead of files")
    p.add_argument("--dmax", type=float, metavar="N", help="largest disparity, left-view px")
    p.add_argument("--init", metavar="SPEC", help="initial foreground, left-view pixels: auto "
                   "(found from the first consensus; the default without an ellipse), "
                   "point:X,Y (the object under this pixel), box:X0,Y0,X1,Y1 (the object in "
                   "this box), ellipse:CX,CY,RX,RY (read as the box around it; as itself "
                   "with --param refine_ellipse=false) or mask:PATH (8-bit PNG, 255 = "
                   "foreground)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--arch", default=DEFAULT_ARCH, metavar="ARCH",
                   help=f"Taichi backend: {', '.join(ARCHES)} (default {DEFAULT_ARCH}: CUDA if a "
                        f"device answers, else the CPU)")
    p.add_argument("--threads", type=int, metavar="N", help="CPU threads (default: all)")
    p.add_argument("--max-iterations", type=int, metavar="N", help="iteration cap")
    p.add_argument("--params", choices=("default", "paper"), default="default",
                   help="the parameter set: default (recommended) or paper (the paper's "
                        "method and nothing beyond it, Params.paper)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override a solver parameter (repeatable), e.g. --param mu=3")
    p.add_argument("--no-refine", action="store_true",
                   help="disparity.pfm keeps the two quadratics (the paper's model) instead "
                        "of refining each layer by its own matches")
    p.add_argument("--photo", action="store_true",
                   help="a whole photo: solve the object under --init in a window around it "
                        "(outside it disparity.pfm is inf and layers.png 255); --param "
                        "front_margin=4 adds a layer for what stands in front of the object")
    p.add_argument("--calib", metavar="FILE", help="the cameras' calibration, Middlebury's "
                   "calib.txt (cam0, cam1, doffs, baseline, width, height): also writes "
                   "depth.pfm, cloud.ply and object.ply, in the baseline's unit")
    p.add_argument("--focal", type=float, metavar="F", help="instead of --calib: the focal "
                   "length, pixels (with --baseline)")
    p.add_argument("--baseline", type=float, metavar="B", help="instead of --calib: the "
                   "baseline, in the unit wanted for depth (with --focal)")
    p.add_argument("--cx", type=float, metavar="X", help="the left principal point's x, "
                   "pixels (default: the image's centre)")
    p.add_argument("--cy", type=float, metavar="Y", help="its y (default: the image's centre)")
    p.add_argument("--doffs", type=float, default=0.0, metavar="D",
                   help="cx1 - cx0, pixels (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=main_solve)


def _calibration(args, left):
    """The :class:`~lss_kernels.calib.Calibration` of ``--calib`` or ``--focal`` and
    ``--baseline`` (None without them), checked against the size of ``left``."""
    from ..calib import Calibration, read_calib
    from ..io import read_image
    by_hand = [f"--{k}" for k in ("focal", "baseline", "cx", "cy")
               if getattr(args, k) is not None] + (["--doffs"] if args.doffs else [])
    if args.calib is not None and by_hand:
        raise CliError(f"--calib: expected a calibration file or --focal and --baseline, "
                       f"got both ({', '.join(by_hand)})")
    if args.calib is None and not by_hand:
        return None
    if args.calib is None:
        for need in ("focal", "baseline"):
            if getattr(args, need) is None:
                raise CliError(f"--{need}: required with {', '.join(by_hand)}")
        try:
            calib = Calibration(focal=args.focal, baseline=args.baseline, cx=args.cx,
                                cy=args.cy, doffs=args.doffs)
        except ValueError as exc:
            raise CliError(f"--{exc}") from None
    else:
        calib = read_calib(args.calib)
    shape = (left if not isinstance(left, (str, os.PathLike)) else read_image(left, "left")).shape
    calib.check_size(shape, "--calib")
    return calib


def _tuple_text(values) -> str:
    """A tuple parameter as ``--param`` reads it: ``"3,9,18"``, nested ``"24:7:8,4:4:2"``."""
    return ",".join(":".join(str(k) for k in v) if isinstance(v, tuple) else str(v)
                    for v in values)


def param_changes(items, defaults) -> dict:
    """``{name: value}`` from ``--param NAME=VALUE`` items, each value read as the type of
    the field of ``defaults`` (a :class:`~lss_kernels.Params`); a one-line ``CliError``
    otherwise."""
    changes = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not hasattr(defaults, name):
            raise CliError(f"--param: expected NAME=VALUE with a parameter of Params, "
                           f"got {item!r}")
        current = getattr(defaults, name)
        try:
            if isinstance(current, tuple):
                # "3,9,18"; nested tuples as "24:9:8,4:4:2"; numbers as the default's
                number = float if any(isinstance(k, float) for k in current) else int
                changes[name] = tuple(tuple(int(k) for k in v.split(":")) if ":" in v
                                      else number(v) for v in value.split(","))
            elif isinstance(current, bool):
                if value.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(value)
                changes[name] = value.lower() in ("true", "1")
            elif isinstance(current, int):
                changes[name] = int(value)
            elif isinstance(current, str):
                changes[name] = value
            else:
                changes[name] = float(value)
        except ValueError:
            expected = type(current).__name__
            if isinstance(current, tuple):
                expected = "tuple, written " + _tuple_text(current)
            raise CliError(f"--param {name}: expected a {expected}, got {value!r}") from None
    return changes


def _params(args):
    from ..params import Params
    defaults = Params.paper() if getattr(args, "params", "default") == "paper" else Params()
    changes = param_changes(args.param, defaults)
    if args.max_iterations is not None:
        changes["max_iterations"] = args.max_iterations
    if getattr(args, "no_refine", False):
        changes["refine"] = False
    return defaults.replace(**changes) if changes else defaults


def _inputs(args):
    """(left, right, d_max, init, init_frame, scene) from the solve/demo arguments."""
    from ..checks.validate import parse_init
    from .jobs import scene_init
    if sum(map(bool, (args.scene, args.images, args.preset))) > 1:
        raise CliError("give one of --scene DIR, --preset NAME or LEFT RIGHT")
    if args.scene or args.preset:
        from ..io import load_scene
        from ..scenes import make_scene
        scene = load_scene(args.scene) if args.scene else make_scene(args.preset)
        d_max = args.dmax if args.dmax is not None else scene.d_max
        init, frame = scene_init(scene, parse_init(args.init) if args.init else None)
        return scene.left, scene.right, d_max, init, frame, scene
    if len(args.images) != 2:
        raise CliError(f"expected LEFT RIGHT (two images) or --scene DIR, got "
                       f"{len(args.images)} image argument(s)")
    if args.dmax is None:
        raise CliError("--dmax: required with LEFT RIGHT" + _range_hint(*args.images))
    init = parse_init(args.init) if args.init else "auto"
    return args.images[0], args.images[1], args.dmax, init, "left", None


def _range_hint(left, right):
    """What the error for a missing ``--dmax`` suggests: the pair's estimated range
    (:func:`lss_kernels.checks.direction.estimate_range`), or nothing when it cannot be had."""
    from ..checks.direction import estimate_range
    from ..checks.validate import check_pair
    try:
        facts = estimate_range(*check_pair(left, right))
    except ValueError:
        return ""
    return (f"; this pair's distinct matches reach {facts['farthest']:.0f} px, so try "
            f"--dmax {facts['d_max']} (an estimate: a layer without texture may lie beyond it)")


class Progress:
    """A progress bar (rich) with the iteration, the boundary's shift and s/iteration."""

    def __init__(self, total, quiet):
        self.quiet = quiet
        self.bar = None
        if quiet:
            return
        from rich.progress import BarColumn, Progress as RichProgress, TextColumn, \
            TimeElapsedColumn
        self.bar = RichProgress(TextColumn("[bold]lss[/] it {task.completed}/{task.total}"),
                                BarColumn(), TextColumn("{task.fields[info]}"),
                                TimeElapsedColumn(), transient=False)
        self.task = self.bar.add_task("solve", total=total, info="")
        self.bar.start()

    def __call__(self, solver, stats):
        if self.bar is not None:
            self.bar.update(self.task, completed=stats["iteration"],
                            info=f"shift {format_shift(stats['boundary_shift'])}  "
                                 f"{stats['seconds']:.3f} s/it")

    def close(self):
        if self.bar is not None:
            self.bar.stop()


def main_solve(args):
    from ..kernels import backend
    from .jobs import Job, run_job
    params = _params(args)
    left, right, d_max, init, init_frame, scene = _inputs(args)
    calib = _calibration(args, left)
    backend.init(arch=args.arch, threads=args.threads)
    has_truth = scene is not None and scene.disp_left is not None and scene.occ_left is not None
    name = scene.name if scene is not None else os.path.basename(os.path.abspath(args.out))
    if args.photo and init_frame == "cyclopean":    # a scene's ellipse, in the left view
        init, init_frame = tuple(scene.init_ellipse), "left"
    job = Job(name, left, right, d_max, init, init_frame, scene if has_truth else None,
              photo=args.photo)
    progress = Progress(params.max_iterations, args.quiet)
    try:
        summary = run_job(job, args.out, params, callback=progress, calib=calib)
    finally:
        progress.close()
    if not args.quiet:
        line = (f"lss solve: {summary['iterations']} iterations ({summary['stop_reason']}), "
                f"{summary['wall_seconds']} s -> {args.out}")
        if "score" in summary:
            line += (f"  occlusion F1 {summary['score']['occ_f1']:.3f}, "
                     f"bad-4.0 {summary['score']['bad4']:.2f}%")
        print(line)
        photometry = summary.get("photometry", {})
        if photometry.get("correct"):
            print(f"lss solve: the views differ by {photometry['difference']:.3f} at their "
                  f"matches; the right one corrected (gain {photometry['gain']:.3f}, "
                  f"vignetting {photometry['vignetting']:+.3f}, offset "
                  f"{photometry['offset']:+.3f})")
        if summary.get("search", {}).get("from_zero"):
            print(f"lss solve: {summary['search']['floor_share']:.0%} of the first matches lie "
                  f"below 4 px; disparities searched from 0 px")
        recovery = summary.get("recovery", {})
        if "first_params" in recovery:
            first = ", ".join(f"{k}={v}" for k, v in recovery["first_params"].items())
            print(f"lss solve: periodic texture on {recovery['periodic']:.0%} of the left "
                  f"image; solved with {first}")
        if recovery.get("retried"):
            again = ", ".join(f"{k}={v}" for k, v in recovery["retry_params"].items())
            print(f"lss solve: the first model collapsed ({recovery['collapse']}); solved "
                  f"again with {again}, kept the "
                  f"{'second' if recovery['kept'] == 'retry' else 'first'} model")
    return 0


def build_parser(command=None):
    """The ``lss`` parser; with ``command`` (a name of :data:`SUBCOMMAND_MODULES` or
    "solve") only that command's sub-parser, else all of them."""
    parser = argparse.ArgumentParser(
        prog="lss", description="Two-layer level-set stereo with exact occlusion geometry "
                                "(Wang & Zickler), as data-parallel Taichi kernels.")
    parser.add_argument("--version", action="version", version=f"lss_kernels {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    if command in (None, "solve"):
        _add_solve(sub)
    for name, module_name in SUBCOMMAND_MODULES.items():
        if command in (None, name):
            importlib.import_module(f"lss_kernels.apps.{module_name}").add_cli(sub)
    return parser


def _command(argv):
    """The command that ``argv`` starts with when it is a known one, else None (the full
    parser then lists every command in its help or its error)."""
    return argv[0] if argv and argv[0] in ("solve", *SUBCOMMAND_MODULES) else None


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command(argv))
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        from ..checks.recovery import WARNINGS
        with warnings.catch_warnings():
            # warnings as one line each; the library's own every time (each pair of a batch)
            for category in WARNINGS:
                warnings.simplefilter("always", category)
            warnings.showwarning = lambda message, *_, **__: print(
                f"lss {args.command}: warning: {message}", file=sys.stderr)
            return int(args.func(args) or 0)
    except (CliError, ValueError, FileNotFoundError, ImportError, TypeError) as exc:
        print(f"lss {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lss {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
