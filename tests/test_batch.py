"""``lss batch`` on Dask: the maps of ``lss solve``, resuming, failures, a worker killed in the
middle of a batch, one-line errors; and ``lss eval --jobs 2`` against ``--jobs 1``."""
import csv
import logging
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

distributed = pytest.importorskip("distributed")

from lss_kernels.apps.batch import run_batch  # noqa: E402
from lss_kernels.apps.cli import main  # noqa: E402
from lss_kernels.params import Params  # noqa: E402
from lss_kernels.scenes import write_scene  # noqa: E402

SCENES = ("s0", "s1", "s2")
ITERATIONS = 5
FAST = Params(max_iterations=ITERATIONS)
#: The workers' CPU threads: those of the in-process tests (Taichi's default, every core),
#: since Taichi's offline cache keys kernels on them too, so that the workers load the
#: kernels of the tiny scenes that earlier tests compiled
THREADS = os.cpu_count()
FILES = {"disparity.pfm", "surface.pfm", "occlusion.png", "foreground.png", "disparity.png",
         "overlay.png", "confidence.pfm", "confidence.png", "layers.png", "layers_overlay.png",
         "summary.json"}
MAPS = ("disparity.pfm", "occlusion.png", "foreground.png")


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Three tiny rendered scene folders."""
    root = tmp_path_factory.mktemp("scenes")
    for seed, name in enumerate(SCENES):
        write_scene(root / name, "tiny", seed=seed)
    return root


@pytest.fixture(scope="module")
def cluster(ti_arch):
    """A local cluster of two worker processes that tests join with ``scheduler``."""
    from lss_kernels.kernels import backend
    backend.restart()       # writes the kernels compiled so far to the cache the workers read
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=logging.CRITICAL) as c:
        yield c


def _batch(folders, out, **kwargs):
    return run_batch(folders, out, params=kwargs.pop("params", FAST), arch="cpu",
                     threads=THREADS, progress=False, **kwargs)


def _complete(out, names):
    """Every pair has its complete folder, and nothing else is in ``out``."""
    assert sorted(p.name for p in out.iterdir() if p.name != "failures.csv") == sorted(names)
    for name in names:
        assert {p.name for p in (out / name).iterdir()} == FILES


def _mtimes(out):
    return {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/summary.json")}


@pytest.mark.slow
def test_two_workers_write_the_maps_of_lss_solve(scenes, tmp_path):
    solves = [subprocess.Popen(
        [sys.executable, "-m", "lss_kernels.apps.cli", "solve", "--scene", str(scenes / name),
         "--out", str(tmp_path / "solve" / name), "--arch", "cpu", "--threads", str(THREADS),
         "--param", f"max_iterations={ITERATIONS}", "--quiet"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for name in SCENES]
    report = _batch([scenes / n for n in SCENES], tmp_path / "batch", workers=2)
    assert [p.wait(timeout=120) for p in solves] == [0] * len(SCENES)
    assert sorted(report.solved) == list(SCENES) and not report.failures and report.exit_code == 0
    _complete(tmp_path / "batch", SCENES)
    for name in SCENES:
        for file in MAPS:
            assert ((tmp_path / "batch" / name / file).read_bytes()
                    == (tmp_path / "solve" / name / file).read_bytes()), (name, file)


def test_resume_skips_finished_pairs_and_force_redoes_them(scenes, cluster, tmp_path):
    folders, out = [scenes / n for n in SCENES], tmp_path / "out"
    _batch(folders, out, scheduler=cluster.scheduler_address)
    first = _mtimes(out)
    again = _batch(folders, out, scheduler="tcp://no-cluster-is-needed:1")
    assert (again.solved, sorted(again.skipped)) == ([], list(SCENES))
    shutil.rmtree(out / "s1")
    (out / ".s2.partial-stale").mkdir()             # left by a worker killed earlier
    resumed = _batch(folders, out, scheduler=cluster.scheduler_address)
    assert resumed.solved == ["s1"] and sorted(resumed.skipped) == ["s0", "s2"]
    second = _mtimes(out)
    assert {n: second[n] == first[n] for n in ("s0", "s2")} == {"s0": True, "s2": True}
    forced = _batch(folders, out, scheduler=cluster.scheduler_address, force=True)
    assert sorted(forced.solved) == list(SCENES) and not forced.skipped
    assert all(t != second[n] for n, t in _mtimes(out).items())
    _complete(out, SCENES)


def test_a_failing_pair_goes_to_failures_csv_and_the_others_finish(scenes, cluster, tmp_path,
                                                                   capsys):
    bad = tmp_path / "bad"
    shutil.copytree(scenes / "s2", bad)
    (bad / "left.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    code = main(["batch", str(scenes / "s0"), str(bad), str(scenes / "s1"), "--out", str(out),
                 "--scheduler", cluster.scheduler_address, "--arch", "cpu",
                 "--threads", str(THREADS), "--max-iterations", str(ITERATIONS)])
    assert code == 1
    _complete(out, ("s0", "s1"))
    with open(out / "failures.csv") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["scene", "error"] and len(rows) == 2 and rows[1][0] == "bad"
    assert rows[1][1].startswith("ValueError: ") and "left.png" in rows[1][1]
    captured = capsys.readouterr()
    assert "2 solved, 0 skipped, 1 failed" in captured.out
    assert "lss batch: 3/3 pairs, 1 failed" in captured.err


def test_a_worker_killed_in_the_middle_leaves_no_half_written_folder(scenes, cluster,
                                                                     tmp_path):
    out = tmp_path / "out"
    client = distributed.Client(cluster)
    pids = client.run(os.getpid)
    finished = {}
    batch = threading.Thread(target=lambda: finished.update(report=_batch(
        [scenes / n for n in SCENES], out, scheduler=cluster.scheduler_address,
        # pairs of a few seconds: long enough to be killed in the middle
        params=Params(max_iterations=400, stop_shift=0.0))))
    batch.start()
    deadline = time.monotonic() + 60
    while not (partials := list(out.glob(".*.partial-*"))):
        assert time.monotonic() < deadline, "no pair started"
        time.sleep(0.01)
    name = partials[0].name[1:].split(".partial-")[0]
    running = [address for address, keys in client.processing().items()
               if any(str(key).startswith(f"lss-batch-{name}-") for key in keys)]
    os.kill(pids[running[0]], signal.SIGKILL)
    batch.join(timeout=120)
    client.close()
    report = finished["report"]
    assert sorted(report.solved) == list(SCENES) and not report.failures
    _complete(out, SCENES)


def test_without_dask_one_line_and_exit_2(scenes, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert main(["batch", str(scenes / "s0"), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == 'lss batch needs Dask: pip install -e ".[distributed]"\n'
    assert not (tmp_path / "out").exists()
    assert main(["eval", str(scenes), "--jobs", "2", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == ('lss eval: error: --jobs 2 needs Dask: '
                                       'pip install -e ".[distributed]"\n')


@pytest.mark.parametrize("line, expected", [
    ("s0 s1", "line 3: expected SCENE_DIR or LEFT RIGHT DMAX CX,CY,RX,RY [NAME], got 2 fields"),
    ("s0/left.png s0/right.png 12 30,20,10", "line 3: expected DMAX > 0 and CX,CY,RX,RY"),
    ("s0/left.png s0/right.png -1 30,20,10,8", "line 3: expected DMAX > 0"),
    ("s0/left.png missing.png 12 30,20,10,8", "line 3: image not found"),
    ("nowhere", "line 3: scene folder not found"),
])
def test_a_malformed_manifest_line_is_one_line_and_exit_2(scenes, tmp_path, capsys, line,
                                                          expected):
    manifest = scenes / "bad-manifest.txt"
    manifest.write_text(f"# pairs\ns0\n{line}  # the bad one\n\n")
    assert main(["batch", "--manifest", str(manifest), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"lss batch: error: --manifest {manifest} ")
    assert expected in err
    assert not (tmp_path / "out").exists()


def test_manifest_pairs_name_their_folders_and_match_scene_folders(scenes, cluster, tmp_path):
    from lss_kernels.apps.batch import read_manifest
    manifest = scenes / "pairs.txt"
    manifest.write_text("s0\ns1/left.png s1/right.png 14 30,24,12,10 pair-one\n")
    pairs = read_manifest(manifest)
    assert [p.name for p in pairs] == ["s0", "pair-one"]
    assert pairs[1].d_max == 14.0 and pairs[1].init == (30.0, 24.0, 12.0, 10.0)
    report = _batch(pairs, tmp_path, scheduler=cluster.scheduler_address)
    assert sorted(report.solved) == ["pair-one", "s0"]


@pytest.mark.slow
def test_eval_on_two_workers_gives_the_table_of_one(tmp_path, ti_arch):
    from lss_kernels.apps.evaluate import run_eval
    for seed, name in enumerate(("a", "b")):
        write_scene(tmp_path / "data" / name, "tiny", seed=seed)
    tables = {}
    for jobs in (1, 2):
        run_eval(tmp_path / "data", methods=("lss",), out=tmp_path / str(jobs), jobs=jobs,
                 arch=ti_arch, params=FAST, progress=False)
        with open(tmp_path / str(jobs) / "results.csv") as f:
            tables[jobs] = [{k: v for k, v in row.items() if k != "seconds"}
                            for row in csv.DictReader(f)]
    assert tables[2] == tables[1] and len(tables[1]) == 3       # two scenes and the mean
