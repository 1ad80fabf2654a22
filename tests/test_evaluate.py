"""``lss eval``: every method on two tiny rendered scenes, the reports it writes, resuming,
``--force``, the process pool, and one-line errors."""
import argparse
import csv
import json
import sys

import pytest

from lss_kernels.apps.baselines import OPENCV_MISSING
from lss_kernels.apps.evaluate import COLUMNS, METHOD_NAMES, add_cli, run_eval
from lss_kernels.io import save_scene
from lss_kernels.params import Params
from lss_kernels.scenes import make_scene

pytest.importorskip("cv2")

SCENES = ("sceneA", "sceneB")
FAST = Params(max_iterations=10)
PAPER = {"SGM": {"occ_f1": [0.11, 0.22], "avg_occ_f1": 0.165, "avg_bad4": 17.57},
         "Ours (paper)": {"occ_f1": [0.87, 0.60], "avg_occ_f1": 0.735, "avg_bad4": 16.07}}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Two tiny rendered scenes; sceneA is the paper's scene 2, with a two-row paper table."""
    root = tmp_path_factory.mktemp("dataset")
    for seed, name in enumerate(SCENES):
        save_scene(root / name, make_scene("tiny", seed=seed))
    meta_file = root / "sceneA" / "meta.json"
    meta = json.loads(meta_file.read_text())
    meta_file.write_text(json.dumps({**meta, "paper_scene": 2}))
    (root / "paper_table1.json").write_text(json.dumps(PAPER))
    return root


@pytest.fixture(scope="module")
def evaluated(dataset, tmp_path_factory, ti_arch):
    """One full evaluation with all three methods (the rows and the output folder)."""
    out = tmp_path_factory.mktemp("eval")
    rows = run_eval(dataset, methods=METHOD_NAMES, out=out, jobs=1, arch=ti_arch,
                    params=FAST, progress=False)
    return rows, out


def _mtimes(out):
    return {p: p.stat().st_mtime_ns for p in sorted((out / "runs").glob("*/*/result.json"))}


def test_rows_and_run_folders(evaluated):
    rows, out = evaluated
    assert [(r["scene"], r["method"]) for r in rows] == [
        (s, m) for s in SCENES for m in METHOD_NAMES]
    for r in rows:
        assert not r["skipped"]
        assert 0.0 <= r["occ_f1"] <= 1.0 and 0.0 <= r["bad4"] <= 100.0 and r["seconds"] > 0
        run = out / "runs" / r["scene"] / r["method"]
        assert {p.name for p in run.iterdir()} == {"disparity.pfm", "occlusion.png",
                                                  "result.json"} | (
            {"confidence.pfm"} if r["method"] == "lss" else set())
        assert 0.0 <= r["flying"] <= 100.0 and r["n_flying"] <= r["n_points"]
        assert json.loads((run / "result.json").read_text())["occ_f1"] == r["occ_f1"]
    lss = [r for r in rows if r["method"] == "lss"]
    assert all(1 <= r["iterations"] <= FAST.max_iterations for r in lss)


def test_results_csv(evaluated):
    rows, out = evaluated
    with open(out / "results.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert tuple(table[0]) == COLUMNS
    assert [(t["scene"], t["method"]) for t in table] == (
        [(s, m) for s in SCENES for m in METHOD_NAMES] + [("mean", m) for m in METHOD_NAMES])
    for method in METHOD_NAMES:
        mean = next(t for t in table if t["scene"] == "mean" and t["method"] == method)
        f1 = [r["occ_f1"] for r in rows if r["method"] == method]
        assert float(mean["occ_f1"]) == pytest.approx(sum(f1) / len(f1), abs=1e-5)


def test_table_md(evaluated):
    rows, out = evaluated
    lines = (out / "table.md").read_text().splitlines()
    header = next(line for line in lines if line.startswith("| scene"))
    assert [c.strip() for c in header.strip("|").split("|")] == (
        ["scene"] + list(METHOD_NAMES) + ["SGM (paper)", "Ours (paper)"])
    scene_a = next(line for line in lines if "sceneA" in line)
    f1 = {r["method"]: r["occ_f1"] for r in rows if r["scene"] == "sceneA"}
    assert scene_a.startswith("| 2: sceneA |")
    assert f"| {f1['sgm']:.2f} |" in scene_a and scene_a.endswith("| 0.22 | 0.60 |")
    scene_b = next(line for line in lines if "sceneB" in line)
    assert scene_b.endswith("| – | – |")  # not a paper scene
    assert any(line.startswith("| **mean F1**") and line.endswith("| 0.22 | 0.60 |")
               for line in lines)
    assert any(line.startswith("| **mean bad-4.0 (%)**") and line.endswith("| 17.57 | 16.07 |")
               for line in lines)
    assert any(line.startswith("| **seconds per scene**") for line in lines)
    flying = {m: sum(r["flying"] for r in rows if r["method"] == m) / len(SCENES)
              for m in METHOD_NAMES}
    assert any(line.startswith("| **mean flying pixels (% of the band's points)** | ")
               and f"| {flying['sgm']:.2f} |" in line for line in lines)
    # a detail table per method: F1, precision, recall, bad-4.0, seconds, iterations
    start = lines.index("## lss, per scene")
    row_a = next(line for line in lines[start:] if line.startswith("| sceneA |"))
    ra = next(r for r in rows if r["scene"] == "sceneA" and r["method"] == "lss")
    assert row_a == (f"| sceneA | {ra['occ_f1']:.2f} | {ra['occ_precision']:.2f} | "
                     f"{ra['occ_recall']:.2f} | {ra['bad4']:.1f} | {ra['seconds']:.1f} | "
                     f"{ra['iterations']} |")


def test_panels(evaluated):
    _, out = evaluated
    import imageio.v3 as iio
    for name in SCENES:
        panel = iio.imread(out / "panels" / f"{name}.png")
        assert panel.ndim == 3 and panel.shape[1] > 4 * panel.shape[0]  # five tiles in a row


def test_resume_skips_then_force_recomputes(dataset, evaluated, ti_arch):
    rows, out = evaluated
    before = _mtimes(out)
    again = run_eval(dataset, methods=METHOD_NAMES, out=out, arch=ti_arch, params=FAST,
                     progress=False)
    assert all(r["skipped"] for r in again)
    assert [r["occ_f1"] for r in again] == [r["occ_f1"] for r in rows]
    assert _mtimes(out) == before
    forced = run_eval(dataset, methods=("sgm",), out=out, force=True, progress=False)
    assert [r["skipped"] for r in forced] == [False, False]
    after = _mtimes(out)
    changed = {p.parent.name for p in after if after[p] != before[p]}
    assert changed == {"sgm"}


def test_process_pool_matches_in_process(dataset, tmp_path, capsys):
    serial = run_eval(dataset, methods=("sgm", "bm-lr"), out=tmp_path / "serial", jobs=1,
                      progress=False)
    pooled = run_eval(dataset, methods=("sgm", "bm-lr"), out=tmp_path / "pool", jobs=2)
    key = lambda r: (r["scene"], r["method"], r["occ_f1"], r["bad4"])
    assert [key(r) for r in pooled] == [key(r) for r in serial]
    progress = capsys.readouterr().err.splitlines()
    assert len(progress) == 4 and progress[-1].startswith("[4/4] ")


@pytest.mark.slow
def test_lss_scenes_of_one_size_share_a_solver_and_match_a_fresh_solve(dataset, tmp_path,
                                                                       monkeypatch):
    from lss_kernels import solve
    from lss_kernels import solver as solver_module
    from lss_kernels.io import load_scene
    from lss_kernels.metrics import score
    built, resets = [], []

    class Counting(solver_module.Solver):
        def __init__(self, *args, **kwargs):
            built.append(1)
            super().__init__(*args, **kwargs)

        def reset(self, *args, **kwargs):
            resets.append(1)
            return super().reset(*args, **kwargs)

    monkeypatch.setattr(solver_module, "Solver", Counting)
    rows = run_eval(dataset, methods=("lss",), out=tmp_path, params=FAST, progress=False)
    assert (len(built), len(resets)) == (1, len(SCENES) - 1)
    row = rows[-1]                      # a reset solver scores as a new one
    scene = load_scene(dataset / row["scene"])
    init, frame = ((scene.init_ellipse_cyclopean, "cyclopean")
                   if scene.init_ellipse_cyclopean is not None else (scene.init_ellipse, "left"))
    result = solve(scene.left, scene.right, scene.d_max, tuple(init), params=FAST,
                   init_frame=frame)
    s = score(result.disparity, result.occlusion, scene)
    assert (row["occ_f1"], row["bad4"]) == (s["occ_f1"], s["bad4"])


@pytest.mark.slow
def test_trace_scores_every_stop_window_and_replays_the_rule(dataset, tmp_path):
    import imageio.v3 as iio
    from lss_kernels.stopping import replay
    params = Params(max_iterations=40, min_iterations=10, stop_window=5, stop_shift=0.5)
    rows = run_eval(dataset, methods=("lss",), out=tmp_path, params=params, progress=False,
                    trace=True)
    n = 0
    for row in rows:
        trace = json.loads((tmp_path / "runs" / row["scene"] / "lss" / "result.json")
                           .read_text())["trace"]
        its = [t["iteration"] for t in trace]
        assert its[-1] == row["iterations"]
        assert all(i % params.stop_window == 0 for i in its[:-1])
        assert trace[-1]["occ_f1"] == pytest.approx(row["occ_f1"])   # the run's own output
        entry, fired = replay(trace, params)        # by the rule or at the cap
        assert fired and entry["iteration"] == row["iterations"]
        n += len(trace)
    with open(tmp_path / "convergence.csv") as f:
        assert len(list(csv.reader(f))) == n + 1
    md = (tmp_path / "convergence.md").read_text()
    assert "| stop_shift | min_iterations |" in md and "| 0.5 | 10 |" in md
    tables = [line for line in md.splitlines() if line.startswith("|")]
    header, separator = tables[0], tables[1]
    assert header.count("|") == separator.count("|")       # a table Markdown renders
    assert iio.imread(tmp_path / "convergence.png").ndim == 3


def test_unknown_method(dataset, tmp_path):
    with pytest.raises(ValueError, match=r"unknown method\(s\) 'kz'; valid: lss, lss-photo, sgm, bm-lr"):
        run_eval(dataset, methods=("sgm", "kz"), out=tmp_path)


def test_no_scenes(tmp_path, capsys):
    with pytest.raises(ValueError, match="no scene folders"):
        run_eval(tmp_path, methods=("sgm",), out=tmp_path / "out")
    assert _cli(["eval", str(tmp_path / "missing"), "--methods", "sgm"]) == 2
    assert capsys.readouterr().err.startswith("lss eval: error: dataset: folder not found")


def _cli(argv):
    parser = argparse.ArgumentParser(prog="lss")
    add_cli(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_cli(dataset, tmp_path, capsys):
    assert _cli(["eval", str(dataset), "--methods", "bm-lr", "--out", str(tmp_path)]) == 0
    assert "| scene | bm-lr |" in capsys.readouterr().out
    assert (tmp_path / "results.csv").exists()


def test_cli_trace_flag_reaches_run_eval(dataset, tmp_path, monkeypatch):
    from lss_kernels.apps import evaluate
    seen = {}

    def fake_run_eval(dataset_dir, **kwargs):
        seen.update(kwargs)
        (tmp_path / "table.md").write_text("table\n")
        return []

    monkeypatch.setattr(evaluate, "run_eval", fake_run_eval)
    assert _cli(["eval", str(dataset), "--methods", "lss", "--out", str(tmp_path),
                 "--trace"]) == 0
    assert seen["trace"] is True
    assert _cli(["eval", str(dataset), "--methods", "lss", "--out", str(tmp_path)]) == 0
    assert seen["trace"] is False
    assert _cli(["eval", str(dataset), "--methods", "lss", "--out", str(tmp_path), "--params",
                 "paper", "--param", "front_margin=4", "--param", "mu=3"]) == 0
    assert seen["params"] == Params.paper(front_margin=4.0, mu=3.0)


def test_cli_one_line_errors(dataset, tmp_path, capsys, monkeypatch):
    assert _cli(["eval", str(dataset), "--methods", "sgm,hsm", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "valid: lss, lss-photo, sgm, bm-lr" in err
    for bad, what in (("nosuch=1", "a parameter of Params"), ("mu=big", "expected a float"),
                      ("front_margin=-1", "params.front_margin")):
        assert _cli(["eval", str(dataset), "--methods", "lss", "--out", str(tmp_path),
                     "--param", bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and what in err
    monkeypatch.setitem(sys.modules, "cv2", None)
    assert _cli(["eval", str(dataset), "--methods", "sgm", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == f"lss eval: error: {OPENCV_MISSING}\n"
    assert not (tmp_path / "runs").exists()


@pytest.mark.slow
def test_a_scene_without_a_start_scores_as_no_answer_and_the_run_goes_on(dataset, tmp_path,
                                                                         ti_arch):
    """``--init auto`` on a textureless pair finds no object: that scene is recorded with
    its error, scored as an unknown map (F1 0, bad-4.0 100 %), and the other is solved."""
    import numpy as np

    from lss_kernels.io import load_scene, read_pfm
    root = tmp_path / "data"
    flat = make_scene("tiny", seed=5)
    flat.left[:] = 0.5
    flat.right[:] = 0.5
    save_scene(root / "flat", flat)
    save_scene(root / "textured", load_scene(dataset / "sceneB"))
    rows = run_eval(root, methods=("lss",), out=tmp_path / "out", jobs=1, arch=ti_arch,
                    params=FAST, progress=False, init="auto")
    by_scene = {r["scene"]: r for r in rows}
    failed = by_scene["flat"]
    assert "no foreground found" in failed["error"] and failed["iterations"] == 0
    assert failed["occ_f1"] == 0.0 and failed["bad4"] == 100.0
    assert "error" not in by_scene["textured"] and by_scene["textured"]["iterations"] > 0
    assert (tmp_path / "out" / "panels" / "flat.png").exists()
    assert np.isinf(read_pfm(tmp_path / "out" / "runs" / "flat" / "lss" / "disparity.pfm")).all()
