"""The scaling benchmark: a tiny in-process run through the Python API, its outputs, and the
pure helpers."""
import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from lss_kernels.apps import bench, bench_report

TINY = dict(sizes=[(56, 40)], size_d=16, disparities=[], disp_size=(56, 40),
            compare=(56, 40, 16), iterations=1, numpy_iterations=1)


def test_tiny_run_returns_the_expected_keys(ti_arch, tmp_path):
    result = bench.run_benchmark(quick=True, arch=ti_arch, overrides=TINY, isolate=False,
                                 out=str(tmp_path), log=lambda *a: None)
    assert len(result["rows"]) == 1 and result["rows"][0]["sweep"] == "compare+size"
    s = bench.summary(result)
    json.dumps(s)  # one JSON object
    for key in ("taichi", "numpy", "speedup"):
        assert set(s[key]) == set(bench.STAGES)
        assert all(v >= 0 for v in s[key].values())
    assert s["taichi_iteration"] > 0 and s["numpy_iteration"] > 0
    assert s["speedup_iteration"] == pytest.approx(s["numpy_iteration"] / s["taichi_iteration"])
    assert s["bandwidth_gbs"] > 0 and s["maxrss_bytes"] > 0
    # the volumes' memory: the host's on the CPU, the device's on a GPU
    on_gpu = ti_arch != "cpu"
    assert result["bandwidth_source"] == ("Taichi copy kernel on " + ti_arch if on_gpu
                                          else "numpy copy")
    row = result["rows"][0]
    # timed in interleaved blocks (QUICK: 2); the fastest block of each implementation counts
    assert s["repeats"] == 2 and len(s["block_taichi"]) == 2 and len(s["block_numpy"]) == 2
    assert row["iteration"] == min(row["block_iterations"]) == min(s["block_taichi"])
    assert s["numpy_iteration"] == pytest.approx(min(s["block_numpy"]))
    assert "block_iterations" not in (tmp_path / "scaling.csv").read_text().splitlines()[0]
    assert row["c_max"] == 8 and row["work"] == 56 * 40 * 8
    assert row["memory_bytes"] >= row["level_bytes"] > 0
    assert row["memory_model_bytes"] == 4 * 56 * 40 * 8 * (3 + 2)
    assert row["memory_ratio"] == pytest.approx(row["memory_bytes"] / row["memory_model_bytes"])
    # d_max 16 disparities asked for, c_max 8 candidates held: half the ratio
    assert row["memory_ratio_dmax"] == pytest.approx(row["memory_ratio"] * 8 / 16)
    for name in ("scaling.csv", "speedup.csv", "results.json", "results.md"):
        assert (tmp_path / name).stat().st_size > 0
    md = (tmp_path / "results.md").read_text()
    assert "Taichi vs numpy" in md
    lines = md.splitlines()
    for i, line in enumerate(lines):           # every table: separator as wide as header
        if line.startswith("|---"):
            assert line.count("|") == lines[i - 1].count("|"), lines[i - 1]


def test_device_bandwidth_copies_through_a_kernel(ti_arch):
    gbs = bench.device_bandwidth(nbytes=8 << 20, repeats=2)
    assert math.isfinite(gbs) and gbs > 0.1


def test_cli_json_keeps_stdout_to_one_json_object(tmp_path):
    """`lss bench --json`: Taichi's import banner and its "Starting on arch" line stay off
    stdout (run in a fresh process, where both would be printed; the benchmark is stubbed)."""
    import subprocess
    import sys
    code = ("import sys; sys.argv = ['lss', 'bench', '--json', '--in-process'];"
            "import lss_kernels.apps.cli as cli, lss_kernels.apps.bench as b;"
            "b.run_benchmark = lambda **k: {'stub': True}; b.summary = lambda r: r;"
            "sys.exit(cli.main(sys.argv[1:]))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {"stub": True}
    assert "Starting on arch" in proc.stderr


def test_plan_merges_repeated_configurations():
    configs = bench.plan(quick=True, threads=[2, 1])
    keys = [(c["width"], c["height"], c["d_max"], c["threads"]) for c in configs]
    assert len(keys) == len(set(keys))
    assert configs[0]["numpy_iterations"] > 0 and configs[0]["sweep"].startswith("compare")
    assert sum(c["numpy_iterations"] > 0 for c in configs) == 1
    assert any(c["threads"] == 1 for c in configs)


def test_fit_exponent_and_plot(tmp_path):
    work = np.array([1e4, 1e5, 1e6])
    assert bench.fit_exponent(work, 3e-9 * work ** 1.05) == pytest.approx(1.05)
    assert math.isnan(bench.fit_exponent([1e4], [1.0]))
    rows = [dict(threads="default", sweep="size", d_max=64, work=w, iteration=1e-8 * w,
                 **{f"stage_{k}": 1e-9 * w for k in bench.STAGES}) for w in work]
    result = dict(rows=rows, arch="cpu", exponents={k: 1.0 for k in bench.STAGES})
    bench_report.plot(result, str(tmp_path / "p.png"))
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"


def test_synthetic_pair_and_cli_registration():
    left, right, init = bench.synthetic_pair(40, 30, 8, seed=3)
    assert left.shape == right.shape == (30, 40, 3) and left.dtype == np.float32
    assert 0.0 <= left.min() and left.max() <= 1.0 and len(init) == 4
    assert not np.array_equal(left, right)
    parser = argparse.ArgumentParser()
    bench.add_cli(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "--quick", "--json", "--threads", "2", "1"])
    assert args.func is bench.main_bench and args.quick and args.json
    assert args.threads == [2, 1] and args.arch == "auto"      # every command: auto


def _demo(name):
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "demos" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _side_by_side():
    return _demo("side_by_side")


def test_side_by_side_table_has_per_scene_ratios_and_medians():
    sbs = _side_by_side()

    def run(seconds, iterations, f1):
        return {"seconds": seconds, "iterations": iterations, "f1": f1}
    rows = [{"scene": "a", "base": run(10.0, 300, 0.8), "head": run(5.0, 100, 0.9)},
            {"scene": "b", "base": run(6.0, 200, 0.6), "head": run(6.0, 200, 0.5)},
            {"scene": "c", "base": run(9.0, 400, 0.7), "head": run(2.0, 120, 0.7)}]
    lines = sbs.render(rows, "abc123").splitlines()
    assert "base = `abc123`" in lines[0]
    assert "| a | 10.0 | 5.0 | 2.00 | 300 | 100 | 0.800 | 0.900 |" in lines
    # medians: base 9.0 s, head 5.0 s, ratio median(2, 1, 4.5) = 2, iterations 300 / 120;
    # F1 means 0.7 / 0.7
    assert lines[-1] == "| **median** (F1: mean) | 9.0 | 5.0 | 2.00 | 300 | 120 | 0.700 | 0.700 |"
    sized = sbs.render(rows, "abc123", cache_bytes={"base": 3 << 20, "head": 150 << 20})
    assert sized.splitlines()[-1] == "Offline cache at the end: base 3 MiB, head 150 MiB"


def test_side_by_side_starts_from_the_true_foregrounds_box_or_centroid(tmp_path):
    import imageio.v3 as iio
    from lss_kernels.scenes import write_scene
    sbs = _side_by_side()
    write_scene(tmp_path, "tiny")               # 64 x 48; its mask replaced by a known one
    fg = np.zeros((48, 64), np.uint8)
    fg[4:10, 6:21] = 255                        # rows 4..9, columns 6..20
    iio.imwrite(tmp_path / "fg_left.png", fg)
    assert sbs.start(tmp_path, "scene") == []
    assert sbs.start(tmp_path, "auto") == ["--init", "auto"]
    assert sbs.start(tmp_path, "gt-box") == ["--init", "box:6,4,21,10"]
    assert sbs.start(tmp_path, "gt-point") == ["--init", "point:13.00,6.50"]
    rows = [{"scene": "a", "base": {"seconds": 2.0, "iterations": 200, "f1": 0.5},
             "head": {"seconds": 1.0, "iterations": 60, "f1": 0.5}}]
    assert "processes, `--init gt-box`, warm caches" in sbs.render(rows, "x", "gt-box")

    # a solve passes the start on to its process and reads the process's summary
    import types
    seen, caches = [], []

    def run(command, **kwargs):
        seen.append(command)
        caches.append(kwargs["env"]["TI_OFFLINE_CACHE_FILE_PATH"])
        out = Path(command[command.index("--out") + 1])
        out.mkdir(parents=True)
        (out / "summary.json").write_text(json.dumps({"iterations": 60,
                                                      "score": {"occ_f1": 0.9}}))
        return types.SimpleNamespace(returncode=0, stderr="")
    sbs.subprocess = types.SimpleNamespace(run=run)
    got = sbs.solve(sbs.ROOT, tmp_path, tmp_path / "head" / "out", tmp_path / "cache" / "head",
                    "cpu", "gt-box")
    assert seen[0][-2:] == ["--init", "box:6,4,21,10"] and "solve" in seen[0]
    assert caches == [str(tmp_path / "cache" / "head")]          # the side's own cache
    assert got["iterations"] == 60 and got["f1"] == 0.9 and got["seconds"] >= 0


def test_side_by_side_exports_a_commit_and_finds_its_entry_point(tmp_path):
    sbs = _side_by_side()
    if not (sbs.ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    tree = sbs.export("HEAD", tmp_path)
    assert (tree / "lss_kernels" / "__init__.py").is_file()
    assert sbs.entry_point(tree) == ("lss_kernels.apps.cli", "main")


def test_setup_time_runs_first_known_new_and_new_bucket_sizes_on_a_fresh_cache_each_repeat(tmp_path):
    """The order of the processes and their caches, with a fake solve; the table's medians
    and the difference new - known."""
    st = _demo("setup_time")
    calls = []
    fake = {"a": [9.0, 3.0], "b": [5.0], "c": [8.0]}

    def run(scene, out, cache, iterations):
        calls.append((scene, cache.name, iterations))
        seen = [c for c in calls if c[0] == scene and c[1] == cache.name]
        return fake[scene][len(seen) - 1] + 0.1 * int(cache.name[-1])
    times = st.measure(("a", "b", "c"), tmp_path, 40, 3, run=run)
    assert calls[:4] == [("a", "cache0", 40), ("a", "cache0", 40), ("b", "cache0", 40),
                         ("c", "cache0", 40)]
    assert [c[1] for c in calls] == ["cache0"] * 4 + ["cache1"] * 4 + ["cache2"] * 4
    assert times["first"] == pytest.approx([9.0, 9.1, 9.2])
    lines = st.table(times, ((320, 240), (328, 236), (400, 300)), 40).splitlines()
    assert lines[2] == "| first size 320x240: every kernel compiled | 9.1 |"
    assert lines[3] == "| the same size again: kernels loaded | 3.1 |"
    assert lines[-2] == "| **a new size adds** | **2.0** |"
    assert lines[-1] == "| **a new size bucket adds** | **5.0** |"
    with pytest.raises(argparse.ArgumentTypeError, match="WIDTHxHEIGHT"):
        st.parse_size("320")


def test_scene_times_solves_a_scene_three_times_with_the_same_answer(tmp_path, fresh_taichi):
    """``demos/scene_times.py``: the reset solver's last run is the first run's answer (the
    CPU is deterministic), timed apart, and the table holds the row and the medians."""
    from lss_kernels.scenes import write_scene
    st = _demo("scene_times")
    write_scene(tmp_path / "a", "tiny", seed=1)
    row = st.time_scene(tmp_path / "a", fresh_taichi)
    assert row["scene"] == "a" and row["size"] == "64x48"
    assert row["f1"] == row["f1_first"] > 0.5
    assert row["first"] > 0 and row["again"] > 0 and row["iterations"] > 0
    assert 0 < row["ms_per_iteration"] * row["iterations"] / 1e3 < row["again"]
    lines = st.table([row], "cpu", "2 CPU cores").splitlines()
    assert lines[0].startswith("Seconds per scene on cpu (2 CPU cores)")
    assert lines[4].startswith("| a | 64x48 | ")
    assert lines[-1].startswith(f"| **median** | | {row['first']:.2f} | {row['again']:.2f} | "
                                f"{row['iterations']} |")


def test_kernel_profile_sums_each_kernels_loops_per_iteration():
    """``demos/kernel_profile.py``: a kernel's loops are summed, its launches are those of
    its most frequent loop, Taichi's host reads of fields are one row."""
    kp = _demo("kernel_profile")
    records = [("_step_c144_0_kernel_0_serial", 0.5), ("_step_c144_0_kernel_1_range_for", 1.0),
               ("_step_c144_0_kernel_0_serial", 0.5), ("_step_c144_0_kernel_1_range_for", 3.0),
               ("fit_c188_0_kernel_1_range_for", 1.0), ("fit_c188_0_kernel_1_range_for", 1.0),
               ("snode_reader_546_kernel_0_serial", 0.0)]
    rows = kp.summarise(records, iterations=2)
    assert [r["kernel"] for r in rows] == ["_step", "fit", "(host reads of a field)"]
    assert rows[0]["ms"] == pytest.approx(2.5) and rows[0]["launches"] == 1.0
    assert rows[0]["share"] == pytest.approx(5.0 / 7.0)
    assert rows[1]["ms"] == pytest.approx(1.0) and rows[2]["launches"] == 0.5
    lines = kp.table(rows, 4.0, "cpu").splitlines()
    assert lines[0] == "Per iteration on cpu: 4.00 ms wall, 3.50 ms in kernels (2.5 launches)."
    assert lines[4] == "| _step | 2.500 | 1.0 | 71.4 % |"
    with pytest.raises(ValueError, match="scene folder or one of"):
        kp.load("no_such_scene")


@pytest.mark.slow
def test_kernel_profile_times_the_iterations_kernels(ti_arch):
    """A profiled run of the tiny scene: the Eq. 2 step, the derivatives (with phi(x +
    delta_theta)), the upward pass, the messages with the consensus and the ray cast with B
    (model/iteration.py's fused stages) launch once per iteration and take time; the profiler
    is switched off again afterwards (its kernels compile apart)."""
    from lss_kernels.kernels import backend
    kp = _demo("kernel_profile")
    try:
        rows, wall = kp.profile(kp.load("tiny"), ti_arch, warmup=2, iterations=3)
    finally:
        backend.init(arch=ti_arch, kernel_profiler=False)
    by_kernel = {r["kernel"]: r for r in rows}
    for name in ("_step", "derivatives", "upward", "consensus", "geometry"):
        assert by_kernel[name]["launches"] == 1.0 and by_kernel[name]["ms"] > 0
    assert wall > 0 and sum(r["share"] for r in rows) == pytest.approx(1.0)


def test_scene_times_against_a_base_alternates_the_sides_and_compares_again_seconds(tmp_path):
    """``demos/scene_times.py --base``: each scene timed by both trees, the first side
    alternating, each with its own cache; the table's ratio is base / head."""
    st = _demo("scene_times")
    calls = []

    def fake_export(rev, into):
        (into / "marker").write_text(rev)
        return into

    def fake_time(tree, folder, arch, cache):
        side = "base" if (tree / "marker").exists() else "head"
        calls.append((folder.name, side, cache.name))
        again = {"base": 3.0, "head": 1.5}[side] * (2 if folder.name == "b" else 1)
        return {"scene": folder.name, "again": again, "iterations": 100 if side == "base" else 40,
                "f1": 0.8 if side == "base" else 0.9}
    st.export, st.time_in_process = fake_export, fake_time
    folders = [tmp_path / "a", tmp_path / "b"]
    assert st.compare(folders, "abc123", "cpu", tmp_path / "t.md") == 0
    assert calls == [("a", "base", "cache-base"), ("a", "head", "cache-head"),
                     ("b", "head", "cache-head"), ("b", "base", "cache-base")]
    lines = (tmp_path / "t.md").read_text().splitlines()
    assert lines[0].startswith("Seconds per scene once the kernels are compiled (`again`), abc123")
    assert lines[4] == "| a | 3.00 | 1.50 | 2.00 | 100 | 40 | 0.800 | 0.900 |"
    assert lines[5] == "| b | 6.00 | 3.00 | 2.00 | 100 | 40 | 0.800 | 0.900 |"
    assert lines[6] == "| **median** (F1: mean) | 4.50 | 2.25 | 2.00 | 100 | 40 | 0.800 | 0.900 |"


def test_kernel_listing_names_the_cache_entries_and_sums_them(tmp_path):
    # an offline cache entry holds its kernel's tasks by name: "<kernel>_c<N>_<K>_kernel_<I>_..."
    cache = tmp_path / "cache"
    cache.mkdir()
    tasks = {"a.tic": b'{"name":"_step_c12_0_kernel_0_range_for"}',
             "b.tic": b'{"name":"snode_reader_391_kernel_0_serial"}',
             "c.tic": b'{"name":"tensor_to_ext_arr_c3_1_kernel_0_range_for"}',
             "ticache.tcb": b"metadata"}
    for name, text in tasks.items():
        (cache / name).write_bytes(b"TIC\0" + text)
    assert sorted(bench._entry_names(str(cache))) == ["_step", "snode_reader_391",
                                                      "tensor_to_ext_arr"]
    listing = dict(rows=[dict(module="model.levelset", kernel="LevelSet._step", instances=1),
                         dict(module="model.levelset", kernel="LevelSet._evolve", instances=2),
                         dict(module=bench.TAICHI_IO, kernel="tensor_to_ext_arr", instances=3)],
                   instances=6, cache_entries=7)
    table = bench.kernel_table(listing)
    assert "| model.levelset | 2 | 3 |" in table and f"| {bench.TAICHI_IO} | 1 | 3 |" in table
    assert table.splitlines()[-1] == ("6 kernel instances; 7 entries in an empty offline "
                                      "cache")
