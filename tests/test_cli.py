"""The ``lss`` parser: a command builds only its own sub-parser, the full help lists all."""
import subprocess
import sys

import pytest

from lss_kernels.apps import cli


@pytest.mark.parametrize("argv, command", [
    (["solve", "a.png", "b.png"], "solve"),
    (["eval", "DIR", "--methods", "lss"], "eval"),
    (["batch", "--help"], "batch"),
    (["--version"], None),
    (["-h", "solve"], None),
    (["sovle", "x"], None),
])
def test_the_command_is_the_first_word_when_it_is_known(argv, command):
    assert cli._command(argv) == command


def _subcommands(parser):
    actions = [a for a in parser._actions if a.dest == "command"]
    return sorted(actions[0].choices)


def test_a_command_builds_only_its_own_parser_and_none_builds_all():
    assert _subcommands(cli.build_parser("solve")) == ["solve"]
    assert _subcommands(cli.build_parser("eval")) == ["eval"]
    assert _subcommands(cli.build_parser()) == ["batch", "bench", "demo", "eval", "solve"]


def test_lss_solve_does_not_import_the_other_commands_modules():
    code = ("import sys; from lss_kernels.apps import cli; cli.build_parser('solve'); "
            "print(sorted(m for m in ('matplotlib', 'cv2', 'dask', 'lss_kernels.apps.demo') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_an_unknown_command_is_told_every_valid_one(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["sovle"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "'sovle'" in err and all(c in err for c in ("solve", "demo", "eval", "bench", "batch"))


def test_params_paper_is_the_papers_method_and_the_default_is_params():
    """``--params paper`` on ``lss solve`` gives :meth:`Params.paper`, ``--param`` still
    overrides it; without it, ``Params()``."""
    from lss_kernels import Params
    parser = cli.build_parser("solve")
    args = parser.parse_args(["solve", "l.png", "r.png", "--out", "o"])
    assert cli._params(args) == Params()
    args = parser.parse_args(["solve", "l.png", "r.png", "--out", "o", "--params", "paper",
                              "--param", "mu=3"])
    assert cli._params(args) == Params.paper(mu=3.0)
    with pytest.raises(SystemExit):
        parser.parse_args(["solve", "l.png", "--out", "o", "--params", "fast"])


def test_lss_eval_passes_params_paper_to_the_evaluation(monkeypatch, tmp_path):
    from lss_kernels import Params
    from lss_kernels.apps import evaluate
    seen = {}

    def run_eval(dataset_dir, **kwargs):
        seen.update(kwargs)
        (tmp_path / "table.md").write_text("")
        return []

    monkeypatch.setattr(evaluate, "run_eval", run_eval)
    assert cli.main(["eval", "DIR", "--params", "paper", "--out", str(tmp_path)]) == 0
    assert seen["params"] == Params.paper()
    assert cli.main(["eval", "DIR", "--out", str(tmp_path)]) == 0
    assert seen["params"] is None                      # run_eval's default: Params()
