"""Set-up time of whole ``lss solve`` processes: a first size, the same size again, new sizes.

    python demos/setup_time.py [--sizes 320x240 328x236 400x300] [--iterations 40] [--repeats 3]

Each repeat starts from an empty Taichi kernel cache (a temporary ``TI_OFFLINE_CACHE_FILE_PATH``)
and runs four processes of this environment's ``lss solve`` on rendered scenes
(:func:`lss_kernels.scenes.write_scene`), all stopped after the same number of iterations:

1. ``first``: the first size, every kernel compiled;
2. ``known``: the first size again, every kernel loaded from the cache;
3. ``new``: the second size, after the first -- what a user with pairs of mixed sizes pays
   for each new one.  ``new - known`` is the set-up that a new size adds; with the default
   sizes the second is in the first's size bucket
   (:func:`lss_kernels.kernels.backend.bucket_shape`);
4. ``bucket``: the third size, in a bucket not seen before.  ``bucket - known`` is what a
   new bucket adds.

The table gives the median wall seconds of each over the repeats.
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CLI = "import sys; from lss_kernels.apps.cli import main; sys.exit(main(sys.argv[1:]))"


def parse_size(text: str) -> tuple:
    """``"WxH"`` -> ``(W, H)``."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 320x240, got {text!r}")
    if width < 64 or height < 48:
        raise argparse.ArgumentTypeError(f"expected at least 64x48, got {text!r}")
    return width, height


def solve_seconds(scene: Path, out: Path, cache: Path, iterations: int) -> float:
    """Wall seconds of one ``lss solve --scene`` process with the kernel cache ``cache``."""
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CLI, "solve", "--scene", str(scene),
                           "--out", str(out), "--arch", "cpu", "--quiet",
                           "--max-iterations", str(iterations)],
                          env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"lss solve on {scene.name} failed (exit {done.returncode}):\n"
                           f"{done.stderr[-2000:]}")
    return seconds


def measure(scenes: tuple, work: Path, iterations: int, repeats: int,
            run=solve_seconds) -> dict:
    """``{"first": [...], "known": [...], "new": [...], "bucket": [...]}`` wall seconds, one
    per repeat, each repeat with an empty cache; ``scenes``: the scene folders of the three
    sizes."""
    times = {"first": [], "known": [], "new": [], "bucket": []}
    for r in range(repeats):
        cache = work / f"cache{r}"
        cache.mkdir()
        for key, scene in zip(times, (scenes[0], scenes[0], scenes[1], scenes[2])):
            times[key].append(run(scene, work / f"out{r}_{key}", cache, iterations))
    return times


def table(times: dict, sizes: tuple, iterations: int) -> str:
    """The markdown table of :func:`measure`'s medians."""
    median = {k: statistics.median(v) for k, v in times.items()}
    (w0, h0), (w1, h1), (w2, h2) = sizes
    lines = [f"| whole `lss solve` process, {iterations} iterations, empty cache first "
             f"(median of {len(times['first'])}) | seconds |", "|---|---|",
             f"| first size {w0}x{h0}: every kernel compiled | {median['first']:.1f} |",
             f"| the same size again: kernels loaded | {median['known']:.1f} |",
             f"| a new size {w1}x{h1} after it | {median['new']:.1f} |",
             f"| a size {w2}x{h2} after both | {median['bucket']:.1f} |",
             f"| **a new size adds** | **{median['new'] - median['known']:.1f}** |",
             f"| **a new size bucket adds** | **{median['bucket'] - median['known']:.1f}** |"]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="setup_time", description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs=3, type=parse_size,
                        default=[(320, 240), (328, 236), (400, 300)], metavar="WxH",
                        help="the first size, a new one (in its bucket by default) and one "
                             "in a new bucket")
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    from lss_kernels.scenes import write_scene
    with tempfile.TemporaryDirectory(prefix="lss_setup_") as tmp:
        work = Path(tmp)
        scenes = []
        for i, (width, height) in enumerate(args.sizes):
            scenes.append(work / f"scene{i}")
            write_scene(scenes[-1], None, width=width, height=height)
        times = measure(tuple(scenes), work, args.iterations, args.repeats)
    print(table(times, tuple(args.sizes), args.iterations))
    return 0


if __name__ == "__main__":
    sys.exit(main())
