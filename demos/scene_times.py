"""Seconds per scene once the kernels are compiled, on any Taichi arch.

    python demos/scene_times.py DATASET [--arch cuda] [--scenes N] [--out table.md]

In one process, each scene folder of ``DATASET`` (its own start, as ``lss solve --scene``)
is solved three times by the same :class:`lss_kernels.Solver`: ``first`` builds the solver
and runs it (a new size bucket compiles or loads its kernels); then
:meth:`~lss_kernels.Solver.reset` on the same pair and a run, twice (the first reset loads
the few kernels of its own), and ``again`` is the second: all kernels in memory, what each
further pair of that size costs.  The table gives both, and of the last run the
iterations, the milliseconds per iteration (``Result.timings``), the set-up and refinement
seconds and the scores.  No pre-check or recovery solve is run (``lss solve`` adds them).
"""
import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
import traceback
from pathlib import Path


def time_scene(folder: Path, arch: str) -> dict:
    """Solve one scene three times (build + run, then reset + run twice); seconds of the
    first and the last, iterations, scores."""
    from lss_kernels import io, metrics
    from lss_kernels.apps.jobs import scene_init
    from lss_kernels.solver import Solver
    scene = io.load_scene(folder)
    init, frame = scene_init(scene)
    start = time.perf_counter()
    solver = Solver(scene.left, scene.right, scene.d_max, init, arch=arch, init_frame=frame)
    first = solver.run()
    first_s = time.perf_counter() - start
    for _ in range(2):
        start = time.perf_counter()
        solver.reset(scene.left, scene.right, scene.d_max, init, init_frame=frame)
        again = solver.run()
        again_s = time.perf_counter() - start
    solver.close()
    scores = [metrics.score(r.disparity, r.occlusion, scene) for r in (first, again)]
    return {"scene": folder.name, "size": f"{scene.left.shape[1]}x{scene.left.shape[0]}",
            "first": first_s, "again": again_s, "iterations": again.iterations,
            "ms_per_iteration": 1e3 * again.timings["iterations_total"] / max(again.iterations, 1),
            "setup": again.timings["setup_total"], "refine": again.timings.get("refine", 0.0),
            "f1_first": float(scores[0]["occ_f1"]), "f1": float(scores[1]["occ_f1"]),
            "bad4": float(scores[1]["bad4"])}


def describe(arch: str) -> str:
    """The device in words: the GPU's name from ``nvidia-smi`` on CUDA, else the CPU count."""
    if arch == "cuda" and shutil.which("nvidia-smi"):
        done = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                              capture_output=True, text=True)
        if done.returncode == 0 and done.stdout.strip():
            return done.stdout.strip().splitlines()[0]
    return f"{os.cpu_count()} CPU cores"


def table(rows: list, arch: str, device: str) -> str:
    lines = [f"Seconds per scene on {arch} ({device}); `again`: the same solver reset and run "
             "again, all kernels compiled.", "",
             "| scene | size | first s | again s | iterations | ms / iteration | set-up s | "
             "refine s | occ F1 | bad-4.0 % |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['size']} | {r['first']:.2f} | {r['again']:.2f} | "
                     f"{r['iterations']} | {r['ms_per_iteration']:.2f} | {r['setup']:.2f} | "
                     f"{r['refine']:.2f} | {r['f1']:.3f} | {r['bad4']:.1f} |")
    if rows:
        med = {k: statistics.median(r[k] for r in rows)
               for k in ("first", "again", "iterations", "ms_per_iteration")}
        lines.append(f"| **median** | | {med['first']:.2f} | {med['again']:.2f} | "
                     f"{med['iterations']:.0f} | {med['ms_per_iteration']:.2f} | | | "
                     f"{statistics.mean(r['f1'] for r in rows):.3f} (mean) | "
                     f"{statistics.mean(r['bad4'] for r in rows):.1f} (mean) |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="folder of scene folders (e.g. paper15)")
    parser.add_argument("--arch", default="cpu", help="Taichi arch (default cpu)")
    parser.add_argument("--scenes", type=int, default=0, help="only the first N scenes")
    parser.add_argument("--out", help="write the table (markdown) here too")
    args = parser.parse_args(argv)
    from lss_kernels import io
    try:
        folders = io.list_scenes(args.dataset)[:args.scenes or None]
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    from lss_kernels.kernels import backend
    arch = backend.init(arch=args.arch)
    device = describe(arch)
    rows, failed = [], 0
    for folder in folders:
        try:
            row = time_scene(folder, arch)
        except Exception:                       # report and go on to the next scene
            failed += 1
            print(f"{folder.name}: failed\n{traceback.format_exc()}", file=sys.stderr)
            continue
        rows.append(row)
        print(f"{row['scene']}: first {row['first']:.2f} s, again {row['again']:.2f} s, "
              f"{row['iterations']} iterations, {row['ms_per_iteration']:.2f} ms each, "
              f"F1 {row['f1']:.3f}", flush=True)
        if args.out:                            # the table so far, should the run be cut off
            Path(args.out).write_text(table(rows, arch, device) + "\n")
    print(table(rows, arch, device))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
