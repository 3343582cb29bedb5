"""The examples run: plot_recording.py draws a recording's block heights (when matplotlib is
installed); webcam_hand.py's joints from a synthetic MediaPipe hand are a hand the source
takes (its camera loop needs a camera, so it is not run)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from argparse import Namespace
from pathlib import Path

import numpy as np
import pytest

import handblocks as hb
from conftest import REPO

EXAMPLES = REPO / "examples" / "python"


def test_plot_recording_draws_the_block_heights(push_recording: Path, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    out = tmp_path / "heights.png"
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "plot_recording.py"), str(push_recording), "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "1 block(s)" in done.stdout


def test_plot_recording_names_a_bad_file(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"nothing")
    done = subprocess.run([sys.executable, str(EXAMPLES / "plot_recording.py"), str(bad)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "bad.mcap" in done.stderr


def test_the_webcam_trackers_joints_are_a_hand_a_source_takes() -> None:
    spec = importlib.util.spec_from_file_location("webcam_hand", EXAMPLES / "webcam_hand.py")
    webcam = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(webcam)
    # A flat right hand in MediaPipe's camera axes (y down), fingers up in the image.
    landmarks = np.zeros((21, 3))
    for f, x in enumerate([-0.04, -0.02, 0.0, 0.02, 0.04]):
        for k in range(4):
            landmarks[1 + 4 * f + k] = [x, -0.03 - 0.025 * k, 0.0]
    args = Namespace(width=0.6, height=0.4, floor=0.02, z=0.15, reach=0.25, depth_gain=0.3)
    position, rotation = webcam.to_joints(landmarks, np.array([0.5, 0.5]), 0.25, args, True)
    assert position.shape == (26, 3) and rotation.shape == (26, 4)
    assert np.allclose(np.linalg.norm(rotation, axis=1), 1.0)
    # The wrist where the image puts it; the fingers above it (up in the image is up here).
    assert np.allclose(position[hb.JOINT_NAMES.index("wrist")], [0.0, 0.22, 0.15])
    assert position[hb.JOINT_NAMES.index("middle_tip"), 1] > position[1, 1]
