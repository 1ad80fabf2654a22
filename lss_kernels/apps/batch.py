"""``lss batch``: many stereo pairs solved on a Dask distributed cluster.

``lss batch SCENE_DIR... --out DIR`` (or ``--manifest FILE``) solves every pair exactly as
``lss solve --scene SCENE_DIR --out DIR/<scene>`` does (:func:`lss_kernels.apps.jobs.run_job`),
on a local cluster of ``--workers`` processes or on the cluster at ``--scheduler``::

    DIR/<scene>/...        the files of lss solve; summary.json means the pair is done
    DIR/failures.csv       scene, error: the pairs that failed twice (absent when none did)

A manifest names one pair a line: a scene folder, or ``LEFT RIGHT DMAX CX,CY,RX,RY [NAME]``
(two images, the largest disparity and an initial ellipse in left-view pixels; the output
folder is NAME, else the left image's name without its suffix).  Relative paths are read from
the manifest's folder; ``#`` starts a comment; blank lines are ignored.

A pair whose ``summary.json`` exists is skipped unless ``force``.  A worker solves into
``DIR/.<scene>.partial-<random>`` and renames the result into place, so a killed worker never
leaves a half-written ``DIR/<scene>``; the partial folders of killed workers are removed at
the start and at the end of a batch (run one batch at a time into one ``DIR``).  A failing
pair is tried once more (a pair whose worker dies too); the other pairs finish.  Each worker
process starts Taichi once, with ``max(1, cores // worker processes on its host)`` CPU
threads unless told, and keeps its solver for the next pair of the same size
(:class:`lss_kernels.apps.jobs.SolverCache`).
"""
from __future__ import annotations

import csv
import json
import math
import os
import shlex
import shutil
import sys
import tempfile
import time
import uuid
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlparse

__all__ = ["BatchReport", "Pair", "add_cli", "dask_client", "main_batch", "read_manifest",
           "require_dask", "run_batch", "threads_here", "worker_threads"]

#: What a temporary output folder has in its name: ``.<scene>.partial-<random>``.
PARTIAL = ".partial-"
MANIFEST_LINE = "SCENE_DIR or LEFT RIGHT DMAX CX,CY,RX,RY [NAME]"


# ---------------------------------------------------------------------------------------------
# The Dask engine (also used by lss eval)
# ---------------------------------------------------------------------------------------------

def require_dask(what: str):
    """The ``distributed`` module, or an ImportError whose message says that ``what`` needs
    it and how to install it."""
    try:
        import distributed
    except ImportError:
        raise ImportError(f'{what} needs Dask: pip install -e ".[distributed]"') from None
    return distributed


@contextmanager
def dask_client(workers: int = 1, scheduler: str | None = None, what: str = "lss batch"):
    """A Dask ``Client`` on the cluster at ``scheduler``, or on a new local cluster of
    ``workers`` single-threaded worker processes (closed on exit).  A task of the local
    cluster whose worker dies is tried on one more worker."""
    distributed = require_dask(what)
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler)
        except OSError as exc:
            raise ValueError(f"--scheduler: could not connect to {scheduler!r} "
                             f"({str(exc).splitlines()[0]})") from None
        with client:
            yield client
        return
    import logging

    import dask
    # no Taichi banner from the workers (set before they start: they import this package
    # while starting); their errors are the batch's failures, not log lines; a free HTTP
    # port (8787 may be another cluster's)
    with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                          "distributed.nanny.pre-spawn-environ.ENABLE_TAICHI_HEADER_PRINT": "0"}):
        cluster = distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=logging.CRITICAL)
    with cluster, distributed.Client(cluster) as client:
        yield client


def _host(address: str) -> str:
    """The host of a Dask address (``tcp://10.0.0.5:4321`` -> ``10.0.0.5``)."""
    return urlparse(address).hostname or address


def worker_threads(client, threads: int | None = None) -> dict:
    """CPU threads for the Taichi of each host's workers: ``threads``, else
    ``max(1, cores // worker processes on that host)`` (workers do not oversubscribe)."""
    cores = client.run(os.cpu_count)
    per_host = Counter(_host(address) for address in cores)
    return {_host(a): threads or max(1, (n or 1) // per_host[_host(a)]) for a, n in cores.items()}


def threads_here(threads_by_host: dict) -> int | None:
    """On a worker: its host's entry of :func:`worker_threads` (None, all cores, for a host
    that joined later)."""
    from distributed import get_worker
    return threads_by_host.get(_host(get_worker().address))


def cluster_arch(arch: str, scheduler: str | None) -> str:
    """The arch to send to the workers: resolved here for a local cluster (one probe, one
    line), left to each worker of a cluster joined at ``scheduler``."""
    if scheduler is not None:
        return arch
    from ..kernels import backend
    return backend.resolve(arch, log=lambda line: print(line, file=sys.stderr))


# ---------------------------------------------------------------------------------------------
# Pairs
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Pair:
    """One pair of a batch: a scene folder (``scene``), or two images with the largest
    disparity and an initial ellipse ``(cx, cy, rx, ry)`` in left-view pixels.

    ``name`` is its output folder; ``origin`` says where it was given (for messages)."""

    name: str
    scene: str | None = None
    left: str | None = None
    right: str | None = None
    d_max: float | None = None
    init: tuple | None = None
    origin: str = ""

    @classmethod
    def from_scene(cls, folder, origin: str = "SCENE_DIR") -> "Pair":
        """The pair of a scene folder; raises when it is not one."""
        folder = Path(folder).resolve()
        if not folder.is_dir():
            raise FileNotFoundError(f"{origin}: scene folder not found: {folder}")
        if not (folder / "meta.json").is_file():
            raise ValueError(f"{origin}: expected a scene folder holding meta.json, "
                             f"got {folder}")
        return cls(folder.name, scene=os.fspath(folder), origin=f"{origin} {folder}")

    def job(self):
        """The :class:`lss_kernels.apps.jobs.Job` that ``lss solve`` would run (reads the
        images)."""
        from .jobs import Job, job_from_scene
        if self.scene is not None:
            return job_from_scene(self.scene)
        return Job(self.name, self.left, self.right, self.d_max, self.init)


def _manifest_pair(fields: list, base: Path, where: str) -> Pair:
    """The pair of one manifest line split into ``fields``."""
    if len(fields) == 1:
        return Pair.from_scene(base / fields[0], where)
    if len(fields) not in (4, 5):
        raise ValueError(f"{where}: expected {MANIFEST_LINE}, got {len(fields)} fields: "
                         f"{' '.join(fields)!r}")
    left, right = (base / f for f in fields[:2])
    for image in (left, right):
        if not image.is_file():
            raise FileNotFoundError(f"{where}: image not found: {image}")
    try:
        d_max, init = float(fields[2]), tuple(float(v) for v in fields[3].split(","))
        valid = (d_max > 0 and len(init) == 4 and init[2] > 0 and init[3] > 0
                 and all(map(math.isfinite, (d_max, *init))))
    except ValueError:
        valid = False
    if not valid:
        raise ValueError(f"{where}: expected DMAX > 0 and CX,CY,RX,RY with RX, RY > 0, "
                         f"got {fields[2]!r} and {fields[3]!r}")
    name = fields[4] if len(fields) == 5 else left.stem
    return Pair(name, left=os.fspath(left.resolve()), right=os.fspath(right.resolve()),
                d_max=d_max, init=init, origin=where)


def read_manifest(path) -> list:
    """The pairs of a manifest file (see the module's documentation), in file order."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--manifest: file not found: {path}")
    pairs = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        where = f"--manifest {path} line {number}"
        try:
            fields = shlex.split(line.split("#", 1)[0])
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}: {line!r}") from None
        if fields:
            pairs.append(_manifest_pair(fields, path.parent, where))
    return pairs


def _check_pairs(pairs) -> list:
    """``pairs`` as :class:`Pair` objects (scene folders accepted), with distinct names."""
    pairs = [p if isinstance(p, Pair) else Pair.from_scene(p) for p in pairs]
    if not pairs:
        raise ValueError("pairs: expected at least one scene folder or pair, got none")
    seen = {}
    for pair in pairs:
        if pair.name in seen:
            raise ValueError(f"two pairs would write the same output folder {pair.name!r}: "
                             f"{seen[pair.name].origin} and {pair.origin} (a manifest line "
                             f"can name its output: LEFT RIGHT DMAX INIT NAME)")
        seen[pair.name] = pair
    return pairs


def _size_key(pair: Pair):
    """Sort key that puts the pairs one solver can share next to each other: the image size
    (from the file's header) and the search range."""
    import imageio.v3 as iio

    from ..params import c_max
    try:
        if pair.scene is not None:
            d_max = json.loads(Path(pair.scene, "meta.json").read_text())["d_max"]
            left = Path(pair.scene, "left.png")
        else:
            d_max, left = pair.d_max, pair.left
        return (0, tuple(iio.improps(left).shape[:2]), c_max(d_max), pair.name)
    except Exception:           # an unreadable pair fails on its worker, with its message
        return (1, (), 0, pair.name)


# ---------------------------------------------------------------------------------------------
# On a worker
# ---------------------------------------------------------------------------------------------

#: This worker process's Taichi settings and solver cache.
_WORKER = {"setup": None, "cache": None}


def _worker_cache(arch: str, threads: int | None):
    """This process's :class:`SolverCache`, with Taichi started on ``arch`` with
    ``threads`` (once per process; again, with a new cache, when they change)."""
    from ..kernels import backend
    from .jobs import SolverCache
    if _WORKER["setup"] != (arch, threads):
        if _WORKER["cache"] is not None:
            _WORKER["cache"].close()
        backend.init(arch=arch, threads=threads)
        _WORKER.update(setup=(arch, threads), cache=SolverCache())
    return _WORKER["cache"]


def _replace_folder(new: Path, final: Path, trash: Path) -> None:
    """Rename ``new`` to ``final``, moving an existing ``final`` to ``trash`` first."""
    if final.exists():
        os.replace(final, trash)
    os.replace(new, final)


def _solve_pair(pair: Pair, out: str, params, arch: str, threads_by_host: dict) -> dict:
    """Solve ``pair`` into ``out/<name>`` through a partial folder; returns its summary."""
    from ..checks.recovery import named_warnings
    from .jobs import run_job
    cache = _worker_cache(arch, threads_here(threads_by_host))
    partial = Path(tempfile.mkdtemp(prefix=f".{pair.name}{PARTIAL}", dir=out))
    try:
        with named_warnings(pair.name):
            summary = run_job(pair.job(), partial / "result", params, cache=cache)
        _replace_folder(partial / "result", Path(out) / pair.name, partial / "previous")
    finally:
        shutil.rmtree(partial, ignore_errors=True)
    return summary


# ---------------------------------------------------------------------------------------------
# The batch
# ---------------------------------------------------------------------------------------------

@dataclass
class BatchReport:
    """What a batch did: the names of the pairs solved and skipped, ``(name, error)`` of
    those that failed, and the seconds from the first submission to the last result."""

    total: int
    solved: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    failures: list = field(default_factory=list)
    seconds: float = 0.0

    @property
    def pairs_per_minute(self) -> float:
        """Pairs finished (solved or failed) per minute of :attr:`seconds`."""
        finished = len(self.solved) + len(self.failures)
        return 60.0 * finished / self.seconds if self.seconds > 0 else 0.0

    @property
    def exit_code(self) -> int:
        """1 when a pair failed, else 0."""
        return 1 if self.failures else 0


class _ProgressLine:
    """One line on stderr, rewritten in place on a terminal: pairs finished of those to
    solve, failures, pairs per minute."""

    def __init__(self, report: BatchReport, enabled: bool):
        self.report, self.enabled = report, enabled
        self.tty = enabled and sys.stderr.isatty()

    def update(self) -> None:
        if not self.enabled:
            return
        r = self.report
        text = (f"lss batch: {len(r.solved) + len(r.failures)}/{r.total - len(r.skipped)} "
                f"pairs, {len(r.failures)} failed, {r.pairs_per_minute:.1f} pairs/min "
                f"({len(r.skipped)} skipped)")
        print("\r" + text if self.tty else text, end="" if self.tty else "\n",
              file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.tty:
            print(file=sys.stderr)


def _error_line(exc: BaseException) -> str:
    """``Type: first line of the message`` of an exception, for failures.csv."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0] if lines else ''}".rstrip(": ")


def _remove_partials(out: Path) -> None:
    """Remove the partial folders of workers that died (``.<scene>.partial-*``)."""
    for partial in out.glob(f".*{PARTIAL}*"):
        shutil.rmtree(partial, ignore_errors=True)


def _write_failures(out: Path, failures: list) -> None:
    """``failures.csv`` (scene, error), or no such file when nothing failed."""
    path = out / "failures.csv"
    if not failures:
        path.unlink(missing_ok=True)
        return
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["scene", "error"])
        writer.writerows(sorted(failures))


def _solve_on(client, todo: list, out: Path, params, arch: str, threads, report, line):
    """Submit the pairs of ``todo`` (same-size pairs in a row) and record them as they
    finish."""
    from distributed import as_completed
    threads_by_host = worker_threads(client, threads)
    start = time.perf_counter()
    futures = {client.submit(_solve_pair, pair, os.fspath(out), params, arch, threads_by_host,
                             key=f"lss-batch-{pair.name}-{uuid.uuid4().hex[:8]}",
                             retries=1): pair
               for pair in sorted(todo, key=_size_key)}
    line.update()
    for future in as_completed(futures):
        name = futures[future].name
        if future.status == "error":
            report.failures.append((name, _error_line(future.exception())))
        else:
            report.solved.append(name)
        report.seconds = time.perf_counter() - start
        line.update()


def run_batch(pairs, out, *, workers: int = 1, scheduler: str | None = None, params=None,
              arch: str = "auto", threads: int | None = None, force: bool = False,
              progress: bool = True) -> BatchReport:
    """Solve every pair into ``out/<name>`` as ``lss solve`` does, on Dask.

    ``pairs``: :class:`Pair` objects or scene folders, of distinct names; ``out``: the
    output folder (created); ``workers``: processes of the local cluster, one thread each
    (unused with ``scheduler``, the address of a running Dask scheduler); ``params``: solver
    parameters (None: the paper's defaults); ``arch``: the workers' Taichi backend;
    ``threads``: CPU threads of each worker's Taichi (None: cores // worker processes on its
    host); ``force``: solve again the pairs whose ``summary.json`` exists; ``progress``:
    the progress line on stderr.

    Raises ImportError (one line) without Dask; ValueError or FileNotFoundError for no
    pairs, a missing scene folder, two pairs of one name, ``workers`` or ``threads`` < 1.
    """
    require_dask("lss batch")
    from ..params import Params
    pairs = _check_pairs(pairs)
    if not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads: expected an integer >= 1 or None, got {threads!r}")
    params = Params() if params is None else params
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _remove_partials(out)
    finished = set() if force else {p.name for p in pairs
                                    if (out / p.name / "summary.json").is_file()}
    todo = [p for p in pairs if p.name not in finished]
    report = BatchReport(len(pairs), skipped=[p.name for p in pairs if p.name in finished])
    line = _ProgressLine(report, progress)
    if todo:
        arch = cluster_arch(arch, scheduler)
        try:
            with dask_client(workers, scheduler) as client:
                _solve_on(client, todo, out, params, arch, threads, report, line)
        finally:
            line.close()
        _remove_partials(out)
    _write_failures(out, report.failures)
    return report


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------

def add_cli(subparsers) -> None:
    """Register ``batch`` on an ``argparse`` sub-parsers object (handler: :func:`main_batch`)."""
    from ..kernels.backend import ARCHES, DEFAULT_ARCH
    p = subparsers.add_parser(
        "batch", help="solve many pairs on a Dask cluster",
        description="Solve every scene folder (or manifest line) as lss solve does, into "
                    "--out/<scene>, on a local Dask cluster or the one at --scheduler. Done "
                    "pairs (summary.json) are skipped unless --force; failures go to "
                    "--out/failures.csv. Needs Dask: pip install -e \".[distributed]\".")
    p.add_argument("scenes", nargs="*", metavar="SCENE_DIR", help="scene folders")
    p.add_argument("--manifest", metavar="FILE",
                   help=f"one pair a line: {MANIFEST_LINE} (# comments; paths relative to "
                        "the file's folder)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local cluster (default 1)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="use the Dask cluster at this scheduler address instead")
    p.add_argument("--arch", default=DEFAULT_ARCH, metavar="ARCH",
                   help=f"Taichi backend: {', '.join(ARCHES)} (default {DEFAULT_ARCH}: CUDA if a "
                        f"device answers, else the CPU)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="CPU threads per worker (default: cores // workers on its host)")
    p.add_argument("--max-iterations", type=int, metavar="N", help="iteration cap")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override a solver parameter (repeatable), e.g. --param mu=3")
    p.add_argument("--force", action="store_true", help="solve again the pairs already done")
    p.add_argument("--quiet", action="store_true", help="no progress line and no summary")
    p.set_defaults(func=main_batch)


def _pairs_of(args) -> list:
    """The pairs named on the command line: SCENE_DIR arguments, then the manifest's."""
    if not args.scenes and not args.manifest:
        raise ValueError("expected SCENE_DIR... or --manifest FILE, got neither")
    pairs = [Pair.from_scene(folder) for folder in args.scenes]
    if args.manifest:
        pairs += read_manifest(args.manifest)
    return pairs


def main_batch(args) -> int:
    """Handler of ``lss batch``: 0 when every pair is done, 1 when some failed, 2 with one
    line on a usage error (or when Dask is missing)."""
    from .cli import CliError, _params
    try:
        require_dask("lss batch")
        if args.workers is not None and args.scheduler:
            raise ValueError("--workers: the cluster at --scheduler has its own workers; "
                             "expected one of --workers and --scheduler, got both")
        workers = 1 if args.workers is None else args.workers
        report = run_batch(_pairs_of(args), args.out, workers=workers,
                           scheduler=args.scheduler, params=_params(args), arch=args.arch,
                           threads=args.threads, force=args.force, progress=not args.quiet)
    except ImportError as exc:
        print(exc, file=sys.stderr)
        return 2
    except (CliError, ValueError, FileNotFoundError) as exc:
        print(f"lss batch: error: {exc}", file=sys.stderr)
        return 2
    if not args.quiet:
        print(f"lss batch: {len(report.solved)} solved, {len(report.skipped)} skipped, "
              f"{len(report.failures)} failed in {report.seconds:.1f} s "
              f"({report.pairs_per_minute:.1f} pairs/min) -> {args.out}"
              + (f"; see {Path(args.out, 'failures.csv')}" if report.failures else ""))
    return report.exit_code
