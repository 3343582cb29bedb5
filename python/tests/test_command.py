"""The console command a pip install puts on the venv's PATH: ``handblocks`` runs the program
the checkout built (or ``$HANDBLOCKS_BIN``), and says what to do when there is none."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import handblocks as hb
from conftest import EXE

COMMAND = Path(sys.executable).parent / "handblocks"


def run(*args: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(COMMAND), *args], capture_output=True, text=True, timeout=60,
                          env={**os.environ, **env})


def test_the_install_puts_a_handblocks_command_beside_python() -> None:
    assert COMMAND.is_file() and os.access(COMMAND, os.X_OK), COMMAND


def test_the_command_runs_the_program() -> None:
    done = run("--version", HANDBLOCKS_BIN=str(EXE))
    assert done.returncode == 0, done.stderr
    assert hb.__version__ in done.stdout


def test_the_command_finds_the_checkouts_program_by_itself() -> None:
    env = {k: v for k, v in os.environ.items() if k != "HANDBLOCKS_BIN"}
    done = subprocess.run([str(COMMAND), "list"], capture_output=True, text=True, timeout=60,
                          env=env)
    assert done.returncode == 0, done.stderr
    assert "grasp-throw" in done.stdout


def test_a_missing_program_is_said_with_what_to_do(tmp_path: Path) -> None:
    done = run("--version", HANDBLOCKS_BIN=str(tmp_path / "nothing-here"))
    assert done.returncode == 2
    assert "is not an executable file" in done.stderr
    assert "set HANDBLOCKS_BIN" in done.stderr
