"""Seconds per scene once the kernels are compiled, on any Taichi arch.

    python demos/scene_times.py DATASET [--arch cuda] [--scenes N] [--out table.md]
    python demos/scene_times.py DATASET --base REV [--scenes N] [--out table.md]

In one process, each scene folder of ``DATASET`` (its own start, as ``lss solve --scene``)
is solved three times by the same :class:`lss_kernels.Solver`: ``first`` builds the solver
and runs it (a new size bucket compiles or loads its kernels); then
:meth:`~lss_kernels.Solver.reset` on the same pair and a run, twice (the first reset loads
the few kernels of its own), and ``again`` is the second: all kernels in memory, what each
further pair of that size costs.  The table gives both, and of the last run the
iterations, the milliseconds per iteration (``Result.timings``), the set-up and refinement
seconds and the scores.  No pre-check or recovery solve is run (``lss solve`` adds them).

With ``--base REV`` the same is measured for the commit ``REV`` (exported with ``git archive``,
as ``side_by_side.py`` does) and for the working tree, side by side in one run: each scene is
timed by both in processes of their own, alternating which goes first, each side with its own
offline cache; the table compares their ``again`` seconds, the cost of a pair once a process
holds its kernels (a robot's loop, ``lss batch``), where ``side_by_side.py`` compares whole
processes.
"""
import argparse
import json
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


def time_in_process(tree: Path, folder: Path, arch: str, cache: Path) -> dict:
    """:func:`time_scene` in a new process that imports the package of ``tree``, with the
    offline cache ``cache``."""
    env = dict(os.environ, PYTHONPATH=str(tree), TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    done = subprocess.run([sys.executable, str(Path(__file__).resolve()), str(folder),
                           "--arch", arch, "--one"], env=env, cwd=tree, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{folder.name} with {tree}: exit {done.returncode}\n"
                           f"{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare_table(pairs: list, base: str) -> str:
    """``again`` seconds, iterations and F1 of the base and the working tree per scene."""
    lines = [f"Seconds per scene once the kernels are compiled (`again`), {base} against the "
             "working tree, measured side by side.", "",
             "| scene | base s | head s | speed-up | base iterations | head iterations | "
             "base F1 | head F1 |", "|---|---|---|---|---|---|---|---|"]
    for b, h in pairs:
        lines.append(f"| {h['scene']} | {b['again']:.2f} | {h['again']:.2f} | "
                     f"{b['again'] / h['again']:.2f} | {b['iterations']} | {h['iterations']} | "
                     f"{b['f1']:.3f} | {h['f1']:.3f} |")
    if pairs:
        med = lambda i, k: statistics.median(p[i][k] for p in pairs)
        ratio = statistics.median(b["again"] / h["again"] for b, h in pairs)
        lines.append(f"| **median** (F1: mean) | {med(0, 'again'):.2f} | {med(1, 'again'):.2f} | "
                     f"{ratio:.2f} | {med(0, 'iterations'):.0f} | {med(1, 'iterations'):.0f} | "
                     f"{statistics.mean(b['f1'] for b, _ in pairs):.3f} | "
                     f"{statistics.mean(h['f1'] for _, h in pairs):.3f} |")
    return "\n".join(lines)


def export(rev: str, into: Path) -> Path:
    """:func:`side_by_side.export` (the demo next to this one): the tree of ``rev``."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "side_by_side", Path(__file__).with_name("side_by_side.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.export(rev, into)


def compare(folders: list, base: str, arch: str, out) -> int:
    """``--base``: both sides on every scene, alternating; prints and writes the table."""
    import tempfile
    root = Path(__file__).resolve().parents[1]
    pairs, failed = [], 0
    with tempfile.TemporaryDirectory(prefix="lss-scene-times-") as tmp:
        base_tree = Path(tmp, "base").resolve()
        base_tree.mkdir()
        trees = {"base": export(base, base_tree), "head": root}
        caches = {side: Path(tmp, f"cache-{side}") for side in trees}
        for i, folder in enumerate(folders):
            order = ("base", "head") if i % 2 == 0 else ("head", "base")
            try:
                row = {side: time_in_process(trees[side], folder.resolve(), arch, caches[side])
                       for side in order}
            except RuntimeError as error:
                failed += 1
                print(error, file=sys.stderr)
                continue
            pairs.append((row["base"], row["head"]))
            print(f"{folder.name}: again {row['base']['again']:.2f} s (base) "
                  f"{row['head']['again']:.2f} s (head)", flush=True)
            if out:
                Path(out).write_text(compare_table(pairs, base) + "\n")
    print(compare_table(pairs, base))
    return 1 if failed else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="folder of scene folders (e.g. paper15), or with "
                        "--one a scene folder")
    parser.add_argument("--arch", default="cpu", help="Taichi arch (default cpu)")
    parser.add_argument("--scenes", type=int, default=0, help="only the first N scenes")
    parser.add_argument("--base", help="also time this commit, side by side")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", help="write the table (markdown) here too")
    args = parser.parse_args(argv)
    from lss_kernels import io
    if args.one:                                # a process of --base: one scene, as JSON
        from lss_kernels.kernels import backend
        print(json.dumps(time_scene(Path(args.dataset), backend.init(arch=args.arch))))
        return 0
    try:
        folders = io.list_scenes(args.dataset)[:args.scenes or None]
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    if args.base:
        return compare(folders, args.base, args.arch, args.out)
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
