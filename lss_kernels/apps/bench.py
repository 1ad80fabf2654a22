"""Scaling benchmark of the solver: ``lss bench``.

Times one solver iteration stage by stage (``Solver(..., profile=True)``) on synthetic
textured two-plane pairs, across image size, disparity range and CPU thread count; separates
set-up (cost volumes, B_occ, edge maps) and Taichi's compile time (the extra time of a warm-up
iteration); fits the scaling exponent of every stage against pixels x disparities; compares
with the numpy specification of one iteration (:mod:`lss_kernels.reference.iteration`) at
400x300 with 64 disparities; and measures the memory bandwidth (a numpy copy on the CPU, a
Taichi copy kernel in device memory on a GPU) to say how close an iteration comes to streaming
its patch-cost volumes once.

``lss bench --kernels [SOLVE ARGS]`` lists instead the kernel instances that one ``lss solve``
compiles (default: ``--preset easy``), by module (the stage), from a fresh process with an
empty offline cache; the count of the cache's entries is the total (:func:`list_kernels`).

Outputs (``--out``): ``scaling.csv`` (one row per configuration and stage), ``speedup.csv``,
``scaling.png`` (log-log seconds vs pixels x disparities with the fitted exponents),
``results.json`` and ``results.md``.

Examples
--------
``lss bench --quick --json`` ; ``lss bench --kernels --scene data/paper15/scene01_monopoly`` ; ``python demos/scaling_benchmark.py --out bench_out``
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np

from ..kernels.backend import ARCHES, DEFAULT_ARCH
from ..model import STAGES
from .bench_report import report, size_series, summary, write_outputs

__all__ = ["add_cli", "bandwidth", "fit_exponent", "kernel_table", "list_kernels", "main",
           "main_bench", "run_benchmark", "synthetic_pair"]


#: Sweeps: ``sizes`` (W, H) at ``size_d`` disparities, ``disparities`` at ``disp_size``, and the
#: Taichi-vs-numpy configuration ``compare`` (W, H, d_max), which also joins the thread sweep.
#: ``iterations`` are timed after the warm-up, ``repeats`` blocks of them; the numpy
#: specification runs ``numpy_iterations`` of the same iteration indices after each block.
FULL = dict(sizes=[(128, 128), (256, 192), (400, 300), (512, 512), (1024, 768)],
            size_d=64, disparities=[32, 64, 128, 256], disp_size=(400, 300),
            compare=(400, 300, 64), iterations=10, numpy_iterations=10, repeats=3)
QUICK = dict(sizes=[(128, 96), (192, 144)], size_d=64, disparities=[], disp_size=(128, 96),
             compare=(400, 300, 64), iterations=3, numpy_iterations=1, repeats=2)


# ---------------------------------------------------------------------------- inputs
def _value_noise(rng, H, W, cells):
    """Smooth random RGB texture ``(H, W, 3)`` in [0, 1]: bilinear value noise, octaves
    averaged."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    total = np.zeros((H, W, 3))
    for cell in cells:
        gy, gx = y / cell, x / cell
        grid = rng.random((int(H / cell) + 2, int(W / cell) + 2, 3))
        iy, ix = gy.astype(np.int64), gx.astype(np.int64)
        fy, fx = (gy - iy)[..., None], (gx - ix)[..., None]
        total += ((1 - fy) * ((1 - fx) * grid[iy, ix] + fx * grid[iy, ix + 1])
                  + fy * ((1 - fx) * grid[iy + 1, ix] + fx * grid[iy + 1, ix + 1]))
    return np.clip(0.1 + 0.8 * total / len(cells), 0.0, 1.0)


def synthetic_pair(width, height, d_max, seed=0):
    """A textured two-plane pair: a fronto-parallel elliptic foreground at ``0.7 d_max`` over
    a slightly slanted background around ``0.25 d_max`` (left-view pixels).

    Returns ``(left, right, init)``: float32 ``(H, W, 3)`` images in [0, 1] and an initial
    ellipse ``(cx, cy, rx, ry)`` (left view) a little smaller than the true one.
    """
    rng = np.random.default_rng(seed)
    H, W = int(height), int(width)
    d_fg = 0.7 * d_max
    b0, b1 = 0.25 * d_max, 0.05 * d_max / max(W, 1)   # background d = b0 + b1 x
    pad = int(math.ceil(d_max)) + 2
    tex_fg = _value_noise(rng, H, W + 2 * pad, (2.0, 6.0))
    tex_bg = _value_noise(rng, H, W + 2 * pad, (2.0, 6.0))
    cx, cy, rx, ry = W / 2.0, H / 2.0, W / 4.0, 0.3 * H
    inside = lambda x, y: ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0
    rows = np.arange(H)[:, None]

    def sample(tex, x):
        xi = np.clip(np.round(x).astype(np.int64) + pad, 0, tex.shape[1] - 1)
        return tex[rows, xi]

    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    left = np.where(inside(x, y)[..., None], sample(tex_fg, x), sample(tex_bg, x))
    # right pixel xr sees the foreground point x = xr + d_fg if it is inside, else the
    # background point x with x - (b0 + b1 x) = xr
    xf = x + d_fg
    xb = (x + b0) / (1.0 - b1)
    right = np.where(inside(xf, y)[..., None], sample(tex_fg, xf), sample(tex_bg, xb))
    init = (cx, cy, 0.8 * rx, 0.8 * ry)
    return left.astype(np.float32), right.astype(np.float32), init


# ---------------------------------------------------------------------------- measurements
def bandwidth(nbytes=256 << 20, repeats=5):
    """Memory bandwidth in GB/s from numpy copies of a large array (read + write counted)."""
    src = np.ones(nbytes // 8)
    dst = np.empty_like(src)
    np.copyto(dst, src)
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        np.copyto(dst, src)
        best = min(best, time.perf_counter() - t)
    return 2.0 * src.nbytes / best / 1e9


def device_bandwidth(nbytes=256 << 20, repeats=5):
    """Bandwidth in GB/s of a Taichi copy kernel between two fields on the arch Taichi runs
    on (read + write counted): on a GPU, the memory the kernels stream from."""
    import taichi as ti

    n = max(1, nbytes // 8)
    src, dst = ti.field(ti.f32), ti.field(ti.f32)
    builder = ti.FieldsBuilder()
    builder.dense(ti.i, n).place(src)
    builder.dense(ti.i, n).place(dst)
    tree = builder.finalize()

    @ti.kernel
    def copy():
        for i in dst:
            dst[i] = src[i]

    try:
        copy()
        ti.sync()
        best = float("inf")
        for _ in range(repeats):
            t = time.perf_counter()
            copy()
            ti.sync()
            best = min(best, time.perf_counter() - t)
    finally:
        tree.destroy()
    return 2.0 * 4 * n / best / 1e9


def fit_exponent(work, seconds):
    """Least-squares slope of log(seconds) against log(work) (``nan`` if fewer than 2
    distinct usable points)."""
    w = np.asarray(work, np.float64)
    s = np.asarray(seconds, np.float64)
    ok = (w > 0) & (s > 0) & np.isfinite(s)
    if ok.sum() < 2 or np.ptp(np.log(w[ok])) == 0:
        return float("nan")
    return float(np.polyfit(np.log(w[ok]), np.log(s[ok]), 1)[0])


def _maxrss_bytes():
    """Peak resident memory of this process: ``VmHWM`` where /proc has it (ru_maxrss on Linux
    keeps the parent's peak across fork + exec), else ``ru_maxrss``."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r if sys.platform == "darwin" else r * 1024)


# iteration 1 compiles most kernels, iteration 2 the upward pass and the prior; up to about
# iteration 6 the prior means still move fast and many patches search their message
# candidates anew (23 % at iteration 3, < 1 % from iteration 7 on a paper15 scene), a cost a
# solve of hundreds of iterations pays once: the timed iterations are the steady state
WARMUP = 6


def measure(width, height, d_max, iterations=3, numpy_iterations=0, seed=0, params=None,
            repeats=1):
    """Time one configuration in this process (Taichi must be initialised).

    Builds a solver on :func:`synthetic_pair` (``setup``: the constructor, including the
    compilation of the set-up kernels), runs ``WARMUP`` iterations, then times ``repeats``
    blocks of ``iterations`` iterations (``iteration``: mean wall seconds per iteration of the
    fastest block; ``stages``: that block's mean seconds per stage from
    ``Solver(profile=True)``; ``block_iterations``: every block's mean).  ``compile`` is the
    warm-up's time minus ``WARMUP`` such iterations: compilation or offline-cache loading of
    the iteration's kernels, and the first searches of the message candidates.  With
    ``numpy_iterations > 0`` the numpy specification, started from the solver's state after
    the warm-up, runs that many iterations after each Taichi block, so both meet the same
    moments of a noisy machine; ``numpy`` holds the stages of its fastest block,
    ``block_numpy`` every block's mean seconds per iteration.  The fastest block is the
    estimate because the noise here only ever adds time (other load, a slower core).
    """
    import taichi as ti
    from ..reference import iteration as npi
    from ..params import Params
    from ..solver import Solver
    params = params if params is not None else Params(max_iterations=10 ** 6, stop_shift=0.0)
    left, right, init = synthetic_pair(width, height, d_max, seed)
    t = time.perf_counter()
    solver = Solver(left, right, d_max, init, params=params, profile=True)
    setup = time.perf_counter() - t
    n, m = max(1, int(iterations)), int(numpy_iterations)
    blocks, numpy_blocks = [], []
    try:
        t = time.perf_counter()
        for _ in range(WARMUP):
            solver.step()
        ti.sync()
        warm = time.perf_counter() - t
        state = npi.state_from_solver(solver) if m > 0 else None
        for _ in range(max(1, int(repeats))):
            before = {k: solver.timings[k] for k in STAGES}
            t = time.perf_counter()
            for _ in range(n):
                solver.step()
            ti.sync()
            blocks.append(((time.perf_counter() - t) / n,
                           {k: (solver.timings[k] - before[k]) / n for k in STAGES}))
            if state is not None:
                tot = {k: 0.0 for k in STAGES}
                for _ in range(m):
                    state, sec = npi.iteration(state, params)
                    for k in STAGES:
                        tot[k] += sec[k]
                numpy_blocks.append({k: v / m for k, v in tot.items()})
        mean, stages = min(blocks, key=lambda b: b[0])
        H, W, C = solver.H, solver.W, solver.c_max
        levels = len(solver.hierarchy.levels)
        out = dict(width=W, height=H, d_max=d_max, c_max=C, levels=levels, setup=setup,
                   compile=max(warm - WARMUP * mean, 0.0), iteration=mean, stages=stages,
                   block_iterations=[b[0] for b in blocks],
                   memory_bytes=int(solver.memory_bytes), level_bytes=4 * H * W * C * levels,
                   iterations=n, repeats=len(blocks))
    finally:
        solver.close()
    if numpy_blocks:
        out["numpy"] = min(numpy_blocks, key=lambda b: sum(b.values()))
        out["block_numpy"] = [sum(b.values()) for b in numpy_blocks]
        out["numpy_iterations"] = m
    out["maxrss_bytes"] = _maxrss_bytes()
    from ..kernels import backend
    if backend.current_arch() not in (None, "cpu"):
        out["bandwidth_gbs"] = device_bandwidth()   # after the RSS reading: it allocates
    return out


def _worker(argv=None):
    """``python -c 'from lss_kernels.apps.bench import _worker; _worker()' JSON``: one configuration
    in a fresh process (its own Taichi init, thread count and peak RSS); prints one line
    ``BENCH_RESULT {...}``."""
    from ..kernels import backend
    cfg = json.loads((argv or sys.argv[1:])[0])
    backend.init(arch=cfg["arch"], threads=cfg.get("threads"),
                 offline_cache=cfg.get("offline_cache", True))
    r = measure(cfg["width"], cfg["height"], cfg["d_max"], cfg.get("iterations", 3),
                cfg.get("numpy_iterations", 0), repeats=cfg["repeats"])
    print("BENCH_RESULT " + json.dumps(r), flush=True)


def _run_isolated(cfg, timeout=900):
    env = dict(os.environ)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    code = "from lss_kernels.apps.bench import _worker; _worker()"
    proc = subprocess.run([sys.executable, "-c", code, json.dumps(cfg)], capture_output=True,
                          text=True, env=env, timeout=timeout)
    for line in proc.stdout.splitlines():
        if line.startswith("BENCH_RESULT "):
            return json.loads(line[len("BENCH_RESULT "):])
    raise RuntimeError(f"bench worker failed for {cfg}: rc={proc.returncode}\n"
                       f"{proc.stderr[-3000:]}{proc.stdout[-2000:]}")


# ---------------------------------------------------------------------------- kernel instances
#: Where a kernel instance comes from, by the module of its ``@ti.kernel``: the paper's stages
#: (``model/``), the building blocks (``kernels/``), Taichi's own field I/O, and the scalar
#: fields that Python reads or writes (``field[None]``: one small kernel each).
TAICHI_IO = "taichi (to_numpy / from_numpy / fill)"
SNODE_ACCESS = "taichi (field[None] from Python)"


def _kernels_worker(argv=None):
    """``python -c 'from lss_kernels.apps.bench import _kernels_worker; _kernels_worker()' OUT
    SOLVE_ARGS...``: run ``lss solve SOLVE_ARGS`` and write to OUT (JSON) every kernel
    instance that Taichi's front end built, as ``[module, name]``."""
    from taichi.lang import kernel_impl
    out, *solve_args = argv or sys.argv[1:]
    built = []
    materialize = kernel_impl.Kernel.materialize

    def recording(self, key=None, args=None, arg_features=None):
        if (key if key is not None else (self.func, 0, self.autodiff_mode)) \
                not in self.compiled_kernels:
            built.append([self.func.__module__, self.func.__qualname__])
        return materialize(self, key, args, arg_features)

    kernel_impl.Kernel.materialize = recording
    from .cli import main as cli_main
    try:
        rc = cli_main(["solve", *solve_args])
    finally:
        with open(out, "w") as f:
            json.dump(built, f)
    sys.exit(rc)


def _entry_names(cache):
    """The kernel name in each entry (``.tic`` file) of a Taichi offline cache folder."""
    import re
    names = []
    for root, _, files in os.walk(cache):
        for name in sorted(files):
            if name.endswith(".tic"):
                with open(os.path.join(root, name), "rb") as f:
                    m = re.search(rb'"name":"([A-Za-z0-9_]+?)_(?:c\d+_\d+_)?kernel_\d',
                                  f.read())
                names.append(m.group(1).decode() if m else "?")
    return names


def list_kernels(solve_args=("--preset", "easy"), timeout=3600):
    """The kernel instances that one ``lss solve SOLVE_ARGS`` compiles, in a fresh process
    with an empty Taichi offline cache.

    Returns a dict: ``rows`` (``module``, ``kernel``, ``instances``; Taichi's accessors of
    ``field[None]`` as one row per accessor name), ``instances`` (the rows' total) and
    ``cache_entries`` (the ``.tic`` files the process wrote: what a new process loads).
    """
    import collections
    import tempfile
    with tempfile.TemporaryDirectory(prefix="lss-kernels-") as tmp:
        out, cache = os.path.join(tmp, "built.json"), os.path.join(tmp, "cache")
        if not any(a == "--out" for a in solve_args):
            solve_args = [*solve_args, "--out", os.path.join(tmp, "solve")]
        env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=cache)
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        code = "from lss_kernels.apps.bench import _kernels_worker; _kernels_worker()"
        proc = subprocess.run([sys.executable, "-c", code, out, *solve_args],
                              capture_output=True, text=True, env=env, timeout=timeout)
        if proc.returncode != 0 or not os.path.exists(out):
            raise RuntimeError(f"lss solve {' '.join(solve_args)} failed: rc={proc.returncode}"
                               f"\n{proc.stderr[-3000:]}")
        with open(out) as f:
            built = collections.Counter(tuple(b) for b in json.load(f))
        entries = _entry_names(cache)
    accessors = collections.Counter(n.split("_")[0] + "_" + n.split("_")[1]
                                    for n in entries if n.startswith("snode_"))
    rows = [dict(module=TAICHI_IO if m.startswith("taichi") else m.replace("lss_kernels.", ""),
                 kernel=k, instances=n) for (m, k), n in sorted(built.items())]
    rows += [dict(module=SNODE_ACCESS, kernel=k, instances=n) for k, n in sorted(accessors.items())]
    return dict(rows=rows, instances=sum(r["instances"] for r in rows),
                cache_entries=len(entries))


def kernel_table(listing):
    """A Markdown table of :func:`list_kernels`: one row per kernel, then one per module."""
    import collections
    lines = ["| module (stage) | kernel | instances |", "|---|---|---:|"]
    lines += [f"| {r['module']} | {r['kernel']} | {r['instances']} |" for r in listing["rows"]]
    per = collections.Counter()
    for r in listing["rows"]:
        per[r["module"]] += r["instances"]
    lines += ["", "| module (stage) | kernels | instances |", "|---|---:|---:|"]
    lines += [f"| {m} | {sum(r['module'] == m for r in listing['rows'])} | {n} |"
              for m, n in sorted(per.items())]
    lines += ["", f"{listing['instances']} kernel instances; {listing['cache_entries']} entries "
                  f"in an empty offline cache"]
    return "\n".join(lines)


# ---------------------------------------------------------------------------- the benchmark
def plan(quick=False, threads=(None,), overrides=None):
    """The list of configurations of a run (dicts for :func:`measure`)."""
    cfg = dict(QUICK if quick else FULL)
    cfg.update(overrides or {})
    threads = list(threads) if threads else [None]
    configs = []

    def add(sweep, w, h, d, t, numpy=False):
        for c in configs:
            if (c["width"], c["height"], c["d_max"], c["threads"]) == (w, h, d, t):
                c["sweep"] += "+" + sweep
                c["numpy_iterations"] = c["numpy_iterations"] or (
                    cfg["numpy_iterations"] if numpy else 0)
                return
        configs.append(dict(sweep=sweep, width=w, height=h, d_max=d, threads=t,
                            iterations=cfg["iterations"], repeats=cfg["repeats"],
                            numpy_iterations=cfg["numpy_iterations"] if numpy else 0))

    t0 = threads[0]
    cw, ch, cd = cfg["compare"]
    add("compare", cw, ch, cd, t0, numpy=True)
    for (w, h) in cfg["sizes"]:
        add("size", w, h, cfg["size_d"], t0)
    dw, dh = cfg["disp_size"]
    for d in cfg["disparities"]:
        add("disparity", dw, dh, d, t0)
    for t in threads[1:]:
        add("threads", cw, ch, cd, t)
    if threads[1:]:
        configs[0]["sweep"] += "+threads"
    for c in configs:
        if not 0 < c["d_max"] < c["width"]:
            raise ValueError(f"bench: d_max must be in (0, width): {c['d_max']} at "
                             f"{c['width']}x{c['height']} ({c['sweep']} sweep)")
    return configs


def run_benchmark(quick=False, arch="cpu", threads=(None,), out=None, log=print,
                  overrides=None, isolate=True, cold=False):
    """Run every configuration of :func:`plan`; returns a JSON-able dict (and writes
    CSV/PNG/MD under ``out``).

    ``isolate``: one fresh process per configuration (its own thread count, peak RSS and
    compile; the default); ``False`` runs them here (Taichi already initialised by the caller,
    one thread setting).  ``cold``: disable Taichi's offline cache in the workers so that
    ``compile`` is the real compile time.  ``overrides`` replace entries of :data:`QUICK` /
    :data:`FULL`.
    """
    t_start = time.perf_counter()
    configs = plan(quick, threads, overrides)
    bw = bandwidth(64 << 20 if quick else 256 << 20)
    source = "numpy copy"
    log(f"memory bandwidth (numpy copy): {bw:.1f} GB/s; {len(configs)} configurations")
    rows, compare = [], None
    for c in configs:
        if isolate:
            r = _run_isolated(dict(c, arch=arch, offline_cache=not cold))
        else:
            r = measure(c["width"], c["height"], c["d_max"], c["iterations"],
                        c["numpy_iterations"], repeats=c["repeats"])
        if "bandwidth_gbs" in r and source == "numpy copy":
            # a GPU: the volumes live in device memory; use its bandwidth from here on
            bw, source = r["bandwidth_gbs"], f"Taichi copy kernel on {arch}"
            log(f"device memory bandwidth ({source}): {bw:.1f} GB/s")
        row = _row(c, r, bw)
        rows.append(row)
        log(f"[{c['sweep']}] {c['width']}x{c['height']} d={c['d_max']} threads="
            f"{row['threads']}: iteration {1e3 * r['iteration']:.2f} ms (stages "
            f"{1e3 * sum(r['stages'].values()):.2f} ms), setup {r['setup']:.2f} s, compile "
            f"{r['compile']:.2f} s, fields {r['memory_bytes'] / 2 ** 20:.1f} MiB, peak RSS "
            f"{r['maxrss_bytes'] / 2 ** 20:.0f} MiB")
        if "numpy" in r and compare is None:
            compare = _compare(r, bw)
            log(f"numpy vs Taichi at {r['width']}x{r['height']} d={r['d_max']}: numpy "
                f"{1e3 * compare['numpy_iteration']:.1f} ms, Taichi "
                f"{1e3 * compare['taichi_iteration']:.2f} ms: {compare['speedup_iteration']:.1f}x")
    result = dict(arch=arch, quick=bool(quick), cpu_count=os.cpu_count(), bandwidth_gbs=bw,
                  bandwidth_source=source, isolated=bool(isolate), offline_cache=not cold,
                  rows=rows)
    first, sized = size_series(rows)
    expo, expo_px = {}, {}
    for k in STAGES + ("iteration",):
        key = k if k == "iteration" else f"stage_{k}"
        expo[k] = fit_exponent([r["work"] for r in first], [r[key] for r in first])
        expo_px[k] = fit_exponent([r["pixels"] for r in sized], [r[key] for r in sized])
    result["exponents"] = expo
    result["exponents_pixels"] = expo_px
    if compare:
        result["compare"] = compare
    result["maxrss_bytes"] = max([_maxrss_bytes()] + [r["maxrss_bytes"] for r in rows])
    result["seconds"] = time.perf_counter() - t_start
    if out:
        write_outputs(result, out)
        log(f"wrote {out}")
    return result


def _row(c, r, bw):
    row = dict(sweep=c["sweep"], width=r["width"], height=r["height"], d_max=r["d_max"],
               c_max=r["c_max"], threads=c["threads"] if c["threads"] else "default",
               pixels=r["width"] * r["height"], work=r["width"] * r["height"] * r["c_max"],
               setup=r["setup"], compile=r["compile"], iteration=r["iteration"],
               block_iterations=r["block_iterations"],
               stage_sum=sum(r["stages"].values()),
               **{f"stage_{k}": r["stages"][k] for k in STAGES})
    # the budget, 4 B x pixels x disparities x (levels + 2), read two ways: with the
    # c_max cyclopean candidates the volumes hold, and with the d_max disparities asked for
    model = 4 * row["pixels"] * r["c_max"] * (r["levels"] + 2)
    model_dmax = 4 * row["pixels"] * r["d_max"] * (r["levels"] + 2)
    row.update(memory_bytes=r["memory_bytes"], memory_model_bytes=model,
               memory_ratio=r["memory_bytes"] / model,
               memory_ratio_dmax=r["memory_bytes"] / model_dmax,
               maxrss_bytes=r["maxrss_bytes"],
               level_bytes=r["level_bytes"],
               stream_seconds=r["level_bytes"] / (bw * 1e9),
               bandwidth_fraction=r["level_bytes"] / (bw * 1e9) / r["iteration"])
    return row


def _compare(r, bw):
    ti_st, np_st = r["stages"], r["numpy"]
    ti_total, np_total = sum(ti_st.values()), sum(np_st.values())
    return dict(width=r["width"], height=r["height"], d_max=r["d_max"], taichi=ti_st,
                numpy=np_st, speedup={k: np_st[k] / ti_st[k] if ti_st[k] > 0 else float("inf")
                                      for k in STAGES},
                taichi_iteration=ti_total, numpy_iteration=np_total,
                speedup_iteration=np_total / ti_total if ti_total > 0 else float("inf"),
                taichi_iteration_wall=r["iteration"], level_bytes=r["level_bytes"],
                stream_seconds=r["level_bytes"] / (bw * 1e9),
                bandwidth_fraction=r["level_bytes"] / (bw * 1e9) / r["iteration"],
                iterations=r["iterations"], numpy_iterations=r["numpy_iterations"],
                repeats=r["repeats"], block_iterations=r["block_iterations"],
                block_numpy=r["block_numpy"])


# ---------------------------------------------------------------------------- CLI
def _configure(p):
    p.add_argument("--arch", default=DEFAULT_ARCH, metavar="ARCH",
                   help=f"Taichi backend: {', '.join(ARCHES)} (default {DEFAULT_ARCH}: CUDA if a "
                        f"device answers, else the CPU)")
    p.add_argument("--quick", action="store_true",
                   help="two small configurations and the numpy comparison")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (per-stage seconds, speedups) on stdout")
    p.add_argument("--out", default=None, help="folder for CSV / PNG / results.md")
    p.add_argument("--threads", type=int, nargs="+", default=None,
                   help="CPU thread counts to sweep (default: Taichi's default)")
    p.add_argument("--cold", action="store_true",
                   help="disable Taichi's offline cache: 'compile' is the real compile time")
    p.add_argument("--kernels", nargs=argparse.REMAINDER, metavar="SOLVE_ARGS",
                   help="list the kernel instances that 'lss solve SOLVE_ARGS' compiles "
                        "(default --preset easy) instead; the remaining arguments go to solve")
    p.add_argument("--in-process", action="store_true",
                   help="run every configuration in this process (one thread setting)")
    return p


def add_cli(subparsers):
    """Register ``bench`` on an argparse subparsers object."""
    p = subparsers.add_parser("bench", help="scaling benchmark of the solver stages",
                              description=__doc__.split("\n\n")[0])
    _configure(p)
    p.set_defaults(func=main_bench)
    return p


def main_bench(args) -> int:
    """Entry point of ``lss bench`` (``args`` from :func:`add_cli`)."""
    from ..kernels import backend
    if args.kernels is not None:
        listing = list_kernels(args.kernels or ("--preset", "easy"))
        print(json.dumps(listing) if args.json else kernel_table(listing))
        return 0
    threads = args.threads or [None]
    if any(t is not None and t < 1 for t in threads):
        raise ValueError(f"--threads: expected positive integers, got {threads}")
    if args.in_process and len(threads) > 1:
        raise ValueError("--in-process: one thread setting only (re-initialising Taichi "
                         "invalidates fields; the default runs a process per configuration)")
    # with --json, stdout carries the one JSON object: Taichi's "Starting on arch" line
    # goes to stderr
    with contextlib.redirect_stdout(sys.stderr) if args.json else contextlib.nullcontext():
        arch = backend.init(arch=args.arch, threads=threads[0], offline_cache=not args.cold)
    log = (lambda *a: print(*a, file=sys.stderr, flush=True)) if args.json else print
    result = run_benchmark(quick=args.quick, arch=arch, threads=threads, out=args.out,
                           log=log, isolate=not args.in_process, cold=args.cold)
    if args.json:
        print(json.dumps(summary(result), default=float))
    else:
        print(report(result))
    return 0


def main(argv=None) -> int:
    """``python -m lss_kernels.apps.bench`` / ``demos/scaling_benchmark.py``."""
    p = _configure(argparse.ArgumentParser(prog="lss bench",
                                           description=__doc__.split("\n\n")[0]))
    return main_bench(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
