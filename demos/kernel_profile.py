"""Where an iteration's time goes, kernel by kernel, on any Taichi arch.

    python demos/kernel_profile.py SCENE [--arch cuda] [--warmup 30] [--iterations 100]

SCENE is a scene folder (as ``lss solve --scene`` reads it) or a preset of the scene
generator (``easy``, ``tiny``, ...).  Taichi starts with its kernel profiler on (the kernels
compile again under it), the solver is built and stepped ``--warmup`` times (kernels loaded,
the first iterations' sweeps done), then the profiler records ``--iterations`` more.  The
table sums each kernel's parallel loops: milliseconds and launches per iteration, and its
share.  The profiler times the loops on the device, not the host's launches: the gap between
their total and the wall time per iteration, printed with it, is what launching costs (most
of an iteration on a GPU at paper sizes, see ``docs/design.md``).
"""
import argparse
import re
import sys
import time
from pathlib import Path

#: Taichi names a kernel's parallel loop ``<kernel>_c<n>_<m>_kernel_<k>_<kind>``.
_LOOP = re.compile(r"^(?P<kernel>.+?)_c\d+_\d+_kernel_\d+_(?P<kind>\w+)$")


def kernel_of(loop_name: str) -> str:
    """The kernel a profiled loop belongs to; Taichi's own readers of a field from the host
    (``snode_reader_...``) are one row; other names stay as they are."""
    if loop_name.startswith("snode_reader"):
        return "(host reads of a field)"
    match = _LOOP.match(loop_name)
    return match.group("kernel") if match else loop_name


def summarise(records, iterations: int) -> list:
    """``(loop name, milliseconds)`` records -> rows per kernel, most costly first:
    ``kernel``, ``ms`` and ``launches`` per iteration (a loop that ran once per launch
    counts its kernel's launches), ``share`` of the total."""
    total = sum(ms for _, ms in records) or 1.0
    rows = {}
    for name, ms in records:
        row = rows.setdefault(kernel_of(name), {"ms": 0.0, "loops": {}})
        row["ms"] += ms
        row["loops"][name] = row["loops"].get(name, 0) + 1
    return sorted(({"kernel": k, "ms": r["ms"] / iterations,
                    "launches": max(r["loops"].values()) / iterations, "share": r["ms"] / total}
                   for k, r in rows.items()), key=lambda r: -r["ms"])


def records_of(profiler) -> list:
    """The loops Taichi's kernel profiler recorded since it was last cleared."""
    profiler._update_records()          # Taichi 1.7 keeps its records behind this
    return [(r.name, float(r.kernel_time)) for r in profiler._traced_records]


def table(rows, wall_ms: float, arch: str) -> str:
    kernels = sum(r["ms"] for r in rows)
    lines = [f"Per iteration on {arch}: {wall_ms:.2f} ms wall, {kernels:.2f} ms in kernels "
             f"({sum(r['launches'] for r in rows):.1f} launches).", "",
             "| kernel | ms / iteration | launches / iteration | share |", "|---|---|---|---|"]
    lines += [f"| {r['kernel']} | {r['ms']:.3f} | {r['launches']:.1f} | {100 * r['share']:.1f} % |"
              for r in rows]
    return "\n".join(lines)


def load(scene: str):
    """A scene folder, or a preset of :func:`lss_kernels.scenes.make_scene`."""
    from lss_kernels import io, scenes
    if Path(scene).is_dir():
        return io.load_scene(scene)
    if scene in scenes.PRESETS:
        return scenes.make_scene(scene)
    raise ValueError(f"SCENE: expected a scene folder or one of {', '.join(scenes.PRESETS)}, "
                     f"got {scene!r}")


def profile(scene, arch: str, warmup: int, iterations: int) -> tuple:
    """Profile ``iterations`` iterations after ``warmup``; returns (rows, wall ms per
    iteration).  The solve must not stop before: its stopping rule is switched off."""
    import taichi as ti
    from taichi.profiler.kernel_profiler import get_default_kernel_profiler
    from lss_kernels import Params
    from lss_kernels.apps.jobs import scene_init
    from lss_kernels.kernels import backend
    from lss_kernels.solver import Solver
    backend.init(arch=arch, kernel_profiler=True)
    init, frame = scene_init(scene)
    params = Params(stop_shift=0.0, max_iterations=warmup + iterations)
    solver = Solver(scene.left, scene.right, scene.d_max, init, params=params,
                    init_frame=frame)
    try:
        for _ in range(warmup):
            solver.step()
        ti.sync()
        ti.profiler.clear_kernel_profiler_info()
        start = time.perf_counter()
        for _ in range(iterations):
            solver.step()
        ti.sync()
        wall = 1e3 * (time.perf_counter() - start) / iterations
        return summarise(records_of(get_default_kernel_profiler()), iterations), wall
    finally:
        solver.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="a scene folder or a preset (easy, tiny, ...)")
    parser.add_argument("--arch", default="cpu", help="Taichi arch (default cpu)")
    parser.add_argument("--warmup", type=int, default=30, help="iterations before (30)")
    parser.add_argument("--iterations", type=int, default=100, help="iterations timed (100)")
    args = parser.parse_args(argv)
    if args.warmup < 1 or args.iterations < 1:
        parser.error("--warmup and --iterations: expected integers >= 1")
    try:
        scene = load(args.scene)
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    rows, wall = profile(scene, args.arch, args.warmup, args.iterations)
    print(table(rows, wall, args.arch))
    return 0


if __name__ == "__main__":
    sys.exit(main())
