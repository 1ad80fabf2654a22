"""``demos/stress_table.py``: docs/stress.md from the results.csv of ``lss eval`` runs."""
import importlib.util
from pathlib import Path

import pytest

HEADER = "scene,method,occ_f1,occ_precision,occ_recall,bad4,bad4_surface,seconds\n"


def _stress_table():
    path = Path(__file__).resolve().parents[1] / "demos" / "stress_table.py"
    spec = importlib.util.spec_from_file_location("stress_table", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _results(folder: Path, rows) -> Path:
    folder.mkdir()
    (folder / "results.csv").write_text(HEADER + "".join(
        f"{scene},{method},{f1},1,1,{bad},0,2\n" for scene, method, f1, bad in rows))
    return folder


def test_families_are_the_means_of_their_scenes_and_the_mean_rows_are_left_out(tmp_path,
                                                                                 capsys):
    folder = _results(tmp_path / "seed0", [
        ("periodic_fg_p3", "lss", 1.0, 0.0), ("periodic_fg_p3", "sgm", 0.5, 20.0),
        ("periodic_bg_p6", "lss", 0.4, 3.0), ("periodic_bg_p6", "sgm", 0.3, 40.0),
        ("weak_fg_grey", "lss", 0.9, 1.0), ("weak_fg_grey", "sgm", "nan", "nan"),
        ("mean", "lss", 0.0, 99.0), ("mean", "sgm", 0.0, 99.0)])
    assert _stress_table().main([str(folder)]) == 0
    page = capsys.readouterr().out
    assert "## seed0" in page and "| mean |" not in page
    # periodic: F1 (1.0 + 0.4) / 2, (0.5 + 0.3) / 2; bad-4.0 1.5 and 30; one lss scene < 0.5
    assert "| periodic | 2 | 0.70 | 0.40 | 1.5 | 30.0 | 1 |" in page
    # a missing score (nan) is left out of the mean and shown as a dash
    assert "| weak | 1 | 0.90 | – | 1.0 | – | 0 |" in page
    assert "| all 3 | 3 | 0.77 | 0.40 | 1.3 | 30.0 | 1 |" in page
    assert "| periodic_bg_p6 | 0.40 | 0.30 | 3.0 | 40.0 |" in page


def test_a_folder_without_results_is_refused_by_name(tmp_path):
    with pytest.raises(SystemExit, match="RESULTS: expected a folder with results.csv"):
        _stress_table().main([str(tmp_path)])


def test_runs_of_the_same_scenes_share_a_section_and_a_single_family_ends_with_its_mean(
        tmp_path, capsys):
    rows = [("periodic_fg_p3", "lss", 1.0, 0.0), ("weak_fg_grey", "lss", 0.4, 2.0)]
    seed0 = _results(tmp_path / "seed0", rows)
    seed1 = _results(tmp_path / "seed1", [(s, m, f1 / 2, bad + 1) for s, m, f1, bad in rows])
    random = _results(tmp_path / "random", [("random_00", "lss", 0.9, 1.0),
                                            ("random_01", "lss", 0.3, 5.0)])
    assert _stress_table().main([str(seed0), str(random), str(seed1)]) == 0
    page = capsys.readouterr().out
    assert "## seed0, seed1" in page and "Each cell: seed0 / seed1." in page
    assert "| periodic_fg_p3 | 1.00 / 0.50 | 0.0 / 1.0 |" in page
    assert "| all 2 | 2 | 0.70 / 0.35 | 1.0 / 2.0 | 1 / 1 |" in page
    assert page.index("## seed0, seed1") < page.index("## random")
    assert "| mean of 2 (lss F1 < 0.5: 1) | 0.60 | 3.0 |" in page
