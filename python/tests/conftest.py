"""What the Python package's tests share: the handblocks binary, the repository, the CARL
traces, and sessions launched with their own bus (own iceoryx2 prefix and root), so tests
run in parallel and leave /dev/shm as they found it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import List, Optional

import pytest

REPO = Path(__file__).resolve().parents[2]
EXE = Path(os.environ.get("HANDBLOCKS_EXE", REPO / "target" / "release" / "handblocks"))
CARL = REPO.parent / "shared" / "data" / "carl"
#: Ceilings only a broken pipeline crosses (tests/support's CEILINGS): no test fails on
#: latency alone on a shared two-core machine.
CEILINGS = ["--set", "budget.origin_to_world_p99_us=20000", "--set", "budget.frame_hz=20"]


def carl(name: str) -> Path:
    path = CARL / f"example_{name}_0.carl"
    if not path.exists():
        pytest.skip(f"{path} is missing (the CARL traces live in ../shared/data/carl)")
    return path


def handblocks(*args: str, check: bool = True, timeout: float = 600) -> subprocess.CompletedProcess:
    """Runs the handblocks binary; output as text."""
    if not EXE.exists():
        pytest.skip(f"{EXE} is missing: build it first (cargo build --release)")
    done = subprocess.run(
        [str(EXE), *args], capture_output=True, text=True, timeout=timeout, cwd=REPO
    )
    if check and done.returncode != 0:
        raise AssertionError(
            f"handblocks {' '.join(args)} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
        )
    return done


def bus_id(tag: str) -> str:
    return f"py{tag}{os.getpid()}"


def launch(*args: str) -> subprocess.Popen:
    """Starts `handblocks launch ARGS` in the background."""
    if not EXE.exists():
        pytest.skip(f"{EXE} is missing: build it first (cargo build --release)")
    return subprocess.Popen(
        [str(EXE), "launch", *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def finish(child: subprocess.Popen, what: str, timeout: float = 120) -> str:
    """Waits for a launched session; its output. Fails when it failed."""
    try:
        out, _ = child.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        child.kill()
        out, _ = child.communicate()
        raise AssertionError(f"{what} did not end in {timeout} s:\n{out}")
    assert child.returncode == 0, f"{what} exited {child.returncode}:\n{out}"
    return out


def nothing_left(bus: str) -> None:
    """No file of session `bus` is left in /dev/shm."""
    left = [f for f in os.listdir("/dev/shm") if f.startswith(f"hb_{bus}_")]
    assert not left, f"left in /dev/shm: {left}"


@pytest.fixture(scope="session")
def push_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording of the CARL push replay (every topic), made once for the tests that read."""
    trace = carl("push")
    out = tmp_path_factory.mktemp("rec") / "push.mcap"
    bus = bus_id("rec")
    child = launch(
        "config/sessions/replay-carl-push.toml", "--bus-id", bus, "--record", str(out), *CEILINGS
    )
    finish(child, "the push replay")
    nothing_left(bus)
    assert trace.exists() and out.exists()
    return out


def json_lines(text: str) -> List[dict]:
    return [json.loads(line) for line in text.splitlines() if line.strip()]
