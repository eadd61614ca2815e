"""The command group: help, version, and the one-line error contract."""

import subprocess
import sys

from click.testing import CliRunner

from cutkit import __version__
from cutkit.cli.commands import COMMANDS
from cutkit.cli.main import cli, main


def test_version():
    result = CliRunner().invoke(cli, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == f"cutkit, version {__version__}"


def test_help_lists_commands_from_the_table():
    result = CliRunner().invoke(cli, ["--help"])
    assert result.exit_code == 0
    for name in cli.list_commands(None):
        assert name in result.output
        assert COMMANDS[name][1][:30] in " ".join(result.output.split())


def test_every_table_entry_has_a_command_module():
    missing = [name for name in COMMANDS if name not in cli.list_commands(None)]
    assert missing == [], f"commands in the table without a module: {missing}"


def test_user_error_is_one_line_without_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "cutkit.cli.main", "info", str(tmp_path / "absent.h5")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("cutkit: error: ") and "absent.h5" in lines[0]


def test_main_returns_exit_code():
    assert main(["--version"]) == 0
    assert main(["no-such-command"]) == 2


def test_the_solver_choices_are_the_tissues_solvers():
    """``--solver`` is one option for simulate, demo and live, its choices and the default its help
    names the element tissue's."""
    from cutkit.cli._ui import SOLVER_CHOICES, SOLVER_DEFAULT
    from cutkit.relax.elastic_tissue import (DEFAULT_SOLVER, REST_FIRST_RTOL, REST_RTOL, REST_UNLOADED_FIRST_RTOL,
                                             SOLVERS)

    assert SOLVER_CHOICES == SOLVERS and SOLVER_DEFAULT == DEFAULT_SOLVER
    # the --solver and --rest-rtol helps say so
    assert (REST_FIRST_RTOL, REST_UNLOADED_FIRST_RTOL, REST_RTOL) == (3e-4, 1e-3, 1e-4)
