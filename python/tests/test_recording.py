"""handblocks.Recording: arrays equal `handblocks inspect`'s counts and the Rust reader's
values (`inspect --samples`), CARL traces read as a replay reads them, and damaged or foreign
files give inspect's named errors."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

import handblocks as hb
from conftest import carl, handblocks, json_lines

ARRAYS = {
    "glove": hb.Recording.glove,
    "tracker": hb.Recording.tracker,
    "joints": hb.Recording.joints,
    "hand": hb.Recording.hand,
    "world": hb.Recording.world,
    "frame": hb.Recording.frame,
    "peer_hand": hb.Recording.peer_hand,
}


def test_topics_and_counts_are_inspects(push_recording: Path) -> None:
    rec = hb.Recording(push_recording)
    assert rec.kind == "mcap" and rec.complete and rec.damage is None
    inspect = json.loads(handblocks("inspect", "--json", str(push_recording)).stdout)
    listed = {t["topic"]: t for t in inspect["topics"]}
    topics = rec.topics()
    assert set(topics) == set(listed)
    for name, t in topics.items():
        for key in ("messages", "gaps", "schema", "bytes", "bytes_per_element"):
            assert t[key] == listed[name][key], (name, key)
        assert t["seconds"] == pytest.approx(listed[name]["seconds"])
        assert len(ARRAYS[name](rec)) == t["messages"], name
    assert topics["world"]["messages"] > 100 and topics["joints"]["messages"] > 100
    assert rec.session and rec.session.endswith("replay-carl-push.toml")


def stamp_of(s: dict) -> tuple:
    st = s["stamp"]
    return (st["seq"], st["source_time_ns"], st["origin_ns"], st["publish_ns"])


def test_world_hand_and_joints_are_the_rust_readers_values(push_recording: Path) -> None:
    rec = hb.Recording(push_recording)
    world = rec.world()
    rust = json_lines(handblocks("inspect", str(push_recording), "--samples", "world").stdout)
    assert len(rust) == len(world)
    assert world.names == ["cube"] or len(world.names) == world.position.shape[1]
    for i, s in enumerate(rust):
        assert (world.seq[i], world.time_ns[i], world.origin_ns[i], world.publish_ns[i]) == stamp_of(s)
        assert world.step[i] == s["step"] and world.grasped_block[i] == s["grasped_block"]
        for b, block in enumerate(s["blocks"]):
            # Bit for bit: the JSON carries each double's shortest round-trip form.
            assert world.position[i, b].tolist() == block["pose"]["position"]
            assert world.rotation[i, b].tolist() == block["pose"]["rotation"]
            assert world.mode[i, b] == block["mode"]
        assert world.finger_points[i].reshape(-1).tolist() == s["finger_points"]

    hand = rec.hand()
    rust = json_lines(handblocks("inspect", str(push_recording), "--samples", "hand").stdout)
    assert len(rust) == len(hand)
    for i, s in enumerate(rust):
        assert (hand.seq[i], hand.time_ns[i], hand.origin_ns[i], hand.publish_ns[i]) == stamp_of(s)
        assert hand.wrist_position[i].tolist() == s["wrist"]["position"]
        assert hand.finger_points[i].reshape(-1).tolist() == s["finger_points"]
        assert hand.palm_vertices[i].reshape(-1).tolist() == s["palm_vertices"]
        assert bool(hand.tracked[i]) == (s["tracked"] != 0)

    joints = rec.joints()
    rust = json_lines(handblocks("inspect", str(push_recording), "--samples", "joints").stdout)
    assert len(rust) == len(joints)
    for i, s in enumerate(rust):
        assert (joints.seq[i], joints.time_ns[i]) == stamp_of(s)[:2]
        for j, pose in enumerate(s["joints"]):
            assert joints.position[i, j].tolist() == pose["position"]
            assert joints.rotation[i, j].tolist() == pose["rotation"]


def test_block_modes_and_names(push_recording: Path) -> None:
    world = hb.Recording(push_recording).world()
    assert world.position.shape == (len(world), len(world.names), 3)
    assert world.rotation.shape == (len(world), len(world.names), 4)
    assert world.mode.dtype == np.uint32
    modes = set(world.modes(0))
    assert "pushed" in modes, modes  # the thumb pushes the cube (config/scenes/carl-push.toml)
    assert set(hb.MODE_NAMES) >= modes


@pytest.mark.parametrize("name", ["lift", "push", "pull", "settle"])
def test_a_carl_trace_reads_as_the_replay_reads_it(name: str) -> None:
    rec = hb.Recording(carl(name))
    assert rec.kind == "carl" and rec.complete
    joints = rec.joints()
    assert rec.topics()["joints"]["messages"] == len(joints) > 100
    assert joints.position.shape == (len(joints), 26, 3)
    assert joints.rotation.shape == (len(joints), 26, 4)
    assert joints.time_ns[0] == 0 and np.all(np.diff(joints.time_ns.astype(np.int64)) > 0)
    assert np.isfinite(joints.position).all()
    assert len(rec.world()) == 0 and rec.world().position.shape == (0, 0, 3)


def test_the_replayed_joints_are_the_trace_moved_by_the_sessions_offset(push_recording: Path) -> None:
    trace = hb.Recording(carl("push")).joints()
    replayed = hb.Recording(push_recording).joints()
    assert len(replayed) == len(trace)
    assert np.array_equal(replayed.time_ns, trace.time_ns)
    offset = np.array([0.0, -1.45, 0.0])  # config/sessions/replay-carl-push.toml
    assert np.array_equal(replayed.position, trace.position + offset)
    assert np.array_equal(replayed.rotation, trace.rotation)


def test_a_cut_recording_is_read_to_its_damage_as_inspect_reads_it(push_recording: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    data = push_recording.read_bytes()
    cut.write_bytes(data[: len(data) * 6 // 10])
    with pytest.warns(hb.RecordingWarning):
        rec = hb.Recording(cut)
    assert not rec.complete and rec.damage
    inspect = handblocks("inspect", "--json", str(cut), check=False)
    assert inspect.returncode == 1
    listed = json.loads(inspect.stdout)
    assert listed["damage"] == rec.damage
    for t in listed["topics"]:
        assert rec.topics()[t["topic"]]["messages"] == t["messages"]
    assert 0 < len(rec.world()) < len(hb.Recording(push_recording).world())


@pytest.mark.parametrize(
    "content", [b"", b"not a recording at all", b"\x89MCA"]
)
def test_files_that_are_no_recording_are_refused_by_name(tmp_path: Path, content: bytes) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    with pytest.raises(hb.RecordingError) as refused:
        hb.Recording(bad)
    assert str(bad) in str(refused.value)


def test_an_mcap_file_cut_after_its_magic_is_damaged_with_nothing_read(tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 3)
    with pytest.warns(hb.RecordingWarning, match="cut off"):
        rec = hb.Recording(cut)
    assert not rec.complete and len(rec.world()) == 0 and len(rec.joints()) == 0
    assert handblocks("inspect", str(cut), check=False).returncode == 1


def test_a_missing_file_and_a_folder_are_refused(tmp_path: Path) -> None:
    with pytest.raises(hb.RecordingError, match="missing.mcap"):
        hb.Recording(tmp_path / "missing.mcap")
    with pytest.raises(hb.RecordingError):
        hb.Recording(tmp_path)
    with pytest.raises(ValueError, match="not a topic"):
        hb.Recording(carl("lift"))._native.arrays("latency")


def test_a_fifo_is_refused_by_kind_instead_of_blocking(tmp_path: Path) -> None:
    # In a Python of its own: a FIFO with no writer used to block Recording() for ever.
    fifo = tmp_path / "lift.fifo"
    os.mkfifo(fifo)
    code = textwrap.dedent(
        f"""
        import handblocks as hb
        try:
            hb.Recording({str(fifo)!r})
            print("read")
        except hb.RecordingError as e:
            print("RecordingError:", e)
        """
    )
    try:
        done = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=30
        )
    except subprocess.TimeoutExpired:
        raise AssertionError("Recording(fifo) still blocked after 30 s") from None
    out = done.stdout + done.stderr
    assert "RecordingError:" in out and "lift.fifo" in out, out
    assert "it is a FIFO (named pipe), not a regular file" in out, out


def test_a_folder_and_a_device_are_refused_by_kind(tmp_path: Path) -> None:
    with pytest.raises(hb.RecordingError, match="it is a folder, not a regular file"):
        hb.Recording(tmp_path)
    with pytest.raises(hb.RecordingError, match="it is a character device, not a regular file"):
        hb.Recording("/dev/zero")
