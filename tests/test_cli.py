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
