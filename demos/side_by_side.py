"""Whole ``lss solve --scene`` processes of two commits, timed side by side in one run.

    python demos/side_by_side.py --base REV --dataset DIR [--scenes N] [--init START] [--out FILE]

The base commit's package is exported with ``git archive`` into a temporary folder and run
through its own ``lss`` entry point (read from its ``pyproject.toml``) with the interpreter
and packages of this environment; the working tree is the other side.  A warm-up pass runs
each side once on every scene (so both find their kernels in Taichi's offline cache, one
cache per side, each side with its own size limit), then each scene is solved by both sides,
alternating which goes first.  The machine's noise
hits both sides alike; the table gives per-scene wall seconds of the whole process,
iterations and occlusion F1 of each, and the median ratio.  ``--init gt-box`` (or
``gt-point``, ``auto``) starts both from the bounding box (centroid) of each scene's true
foreground, or finds the object, instead of the scene's ellipse: a user's box or click.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def export(rev: str, into: Path) -> Path:
    """The tree of ``rev`` written into ``into`` (``git archive``)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def entry_point(tree: Path) -> tuple:
    """``(module, function)`` of the ``lss`` script in ``tree``'s pyproject.toml."""
    scripts = tomllib.loads((tree / "pyproject.toml").read_text())["project"]["scripts"]
    module, function = scripts["lss"].split(":")
    return module, function


def start(scene: Path, init: str) -> list:
    """The ``--init`` arguments of ``lss solve`` for ``init``: none for ``scene`` (its own
    ellipse), ``auto``, or the point / box that ``lss eval --init gt-point / gt-box`` places
    from the scene's true foreground (:func:`lss_kernels.apps.evaluate.scene_start`)."""
    if init in ("scene", "auto"):
        return [] if init == "scene" else ["--init", "auto"]
    from lss_kernels import io
    from lss_kernels.apps.evaluate import scene_start
    place, _ = scene_start(io.load_scene(scene), init)
    if init == "gt-point":
        return ["--init", f"point:{place.x:.2f},{place.y:.2f}"]
    return ["--init", f"box:{place.x0:g},{place.y0:g},{place.x1:g},{place.y1:g}"]


def solve(tree: Path, scene: Path, out: Path, cache: Path, arch: str,
          init: str = "scene") -> dict:
    """One ``lss solve --scene`` process of ``tree``'s package (started as ``init`` says,
    see :func:`start`) with Taichi's offline cache in ``cache``: wall seconds, iterations and
    occlusion F1 (from its summary.json).  It runs in ``out``'s parent, so that the working
    directory cannot shadow ``tree`` on ``sys.path``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    module, function = entry_point(tree)
    code = f"import sys; from {module} import {function} as m; sys.exit(m(sys.argv[1:]))"
    env = dict(os.environ, PYTHONPATH=str(tree), TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    command = [sys.executable, "-c", code, "solve", "--scene", str(scene), "--out", str(out),
               "--arch", arch, "--quiet"] + start(scene, init)
    began = time.perf_counter()
    done = subprocess.run(command, env=env, cwd=out.parent, capture_output=True, text=True)
    seconds = time.perf_counter() - began
    if done.returncode != 0:
        raise RuntimeError(f"{tree.name} on {scene.name} failed (exit {done.returncode}):\n"
                           f"{done.stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    return {"seconds": seconds, "iterations": int(summary["iterations"]),
            "f1": float(summary.get("score", {}).get("occ_f1", float("nan")))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the commit to compare against")
    parser.add_argument("--dataset", required=True, help="folder of scene folders")
    parser.add_argument("--scenes", type=int, default=0, help="only the first N scenes")
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--init", choices=("scene", "gt-box", "gt-point", "auto"),
                        default="scene", help="the start of both sides (default: each "
                        "scene's ellipse)")
    parser.add_argument("--no-warmup", action="store_true",
                        help="skip the unmeasured pass (the caches are already warm)")
    parser.add_argument("--out", help="write the table (markdown) here too")
    args = parser.parse_args(argv)
    # absolute: each process runs in its own output folder
    scenes = sorted(p for p in Path(args.dataset).resolve().iterdir()
                    if (p / "meta.json").is_file())
    if args.scenes:
        scenes = scenes[:args.scenes]
    if not scenes:
        parser.error(f"--dataset: no scene folder in {args.dataset}")
    with tempfile.TemporaryDirectory(prefix="side_by_side_") as tmp:
        tmp = Path(tmp)
        (tmp / "base").mkdir()
        sides = {"base": export(args.base, tmp / "base"), "head": ROOT}
        # each side keeps its kernels in an offline cache of its own, so that one side's
        # cache cleaning (each with its own size limit) cannot evict the other's kernels
        caches = {name: tmp / "cache" / name for name in sides}
        if not args.no_warmup:
            for scene in scenes:
                for name, tree in sides.items():
                    print(f"warm-up {name} {scene.name}", file=sys.stderr, flush=True)
                    solve(tree, scene, tmp / "warm", caches[name], args.arch, args.init)
        rows = []
        for i, scene in enumerate(scenes):
            order = ["base", "head"] if i % 2 == 0 else ["head", "base"]
            row = {"scene": scene.name}
            for name in order:
                row[name] = solve(sides[name], scene, tmp / name / "out", caches[name],
                                  args.arch, args.init)
            rows.append(row)
            print(f"{scene.name}: base {row['base']['seconds']:.1f} s, head "
                  f"{row['head']['seconds']:.1f} s", file=sys.stderr, flush=True)
        sizes = {name: sum(f.stat().st_size for f in caches[name].rglob("*") if f.is_file())
                 for name in sides}
    table = render(rows, args.base, args.init, sizes)
    print(table)
    if args.out:
        Path(args.out).write_text(table)
    return 0


def render(rows, base: str, init: str = "scene", cache_bytes=None) -> str:
    started = "" if init == "scene" else f", `--init {init}`"
    lines = [f"Whole `lss solve --scene` processes{started}, warm caches, base = `{base}`, "
             "head = the working tree (`demos/side_by_side.py`)", "",
             "| scene | base s | head s | speed-up | base iterations | head iterations "
             "| base F1 | head F1 |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b, h = r["base"], r["head"]
        lines.append(f"| {r['scene']} | {b['seconds']:.1f} | {h['seconds']:.1f} | "
                     f"{b['seconds'] / h['seconds']:.2f} | {b['iterations']} | "
                     f"{h['iterations']} | {b['f1']:.3f} | {h['f1']:.3f} |")

    def med(side, key):
        return statistics.median(r[side][key] for r in rows)

    def mean(side, key):
        return statistics.fmean(r[side][key] for r in rows)
    ratio = statistics.median(r["base"]["seconds"] / r["head"]["seconds"] for r in rows)
    lines.append(f"| **median** (F1: mean) | {med('base', 'seconds'):.1f} | "
                 f"{med('head', 'seconds'):.1f} | {ratio:.2f} | "
                 f"{med('base', 'iterations'):.0f} | {med('head', 'iterations'):.0f} | "
                 f"{mean('base', 'f1'):.3f} | {mean('head', 'f1'):.3f} |")
    if cache_bytes:
        lines += ["", "Offline cache at the end: " + ", ".join(
            f"{name} {size / 2 ** 20:.0f} MiB" for name, size in cache_bytes.items())]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
