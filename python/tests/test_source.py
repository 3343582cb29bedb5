"""handblocks.Source: a Python program as the session's `external` source drives it exactly
as the same joints drive `simulate --hand`, with the stamps, checks and counts of any source."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import handblocks as hb
from conftest import CEILINGS, REPO, bus_id, carl, finish, launch, nothing_left

OFFSET = [0.0, -0.92, 0.0]  # config/sessions/replay-carl-lift.toml's


def session_file(tmp_path: Path, command: list) -> Path:
    file = tmp_path / "external.toml"
    file.write_text(
        f'scene = {json.dumps(str(REPO / "config" / "scenes" / "carl-lift.toml"))}\n'
        "[source]\n"
        'kind = "external"\n'
        f"command = {json.dumps(command)}\n"
        "[renderer]\n"
        'mode = "off"\n'
    )
    return file


def test_a_python_source_drives_the_session_as_simulate_hand_does(tmp_path: Path) -> None:
    trace = carl("lift")
    command = [sys.executable, str(Path(__file__).with_name("drive_from_trace.py")), str(trace)]
    command += [str(x) for x in OFFSET]
    bus = bus_id("src")
    rec, report = tmp_path / "run.mcap", tmp_path / "report.json"
    child = launch(
        str(session_file(tmp_path, command)),
        "--bus-id", bus, "--record", str(rec), "--report", str(report), *CEILINGS,
    )
    out = finish(child, "the external source's session")
    nothing_left(bus)
    assert "drive_from_trace: published" in out, out

    played = hb.Recording(trace).joints()
    recording = hb.Recording(rec)
    joints = recording.joints()
    # Stamped as any source's: its own seqs and times, origin and publish on this clock.
    assert len(joints) == len(played)
    assert np.array_equal(joints.seq, np.arange(len(played)))
    assert np.array_equal(joints.time_ns, played.time_ns)
    assert np.array_equal(joints.position, played.position + np.array(OFFSET))
    assert np.all(joints.publish_ns >= joints.origin_ns) and np.all(joints.origin_ns > 0)

    worlds = recording.world()
    tracked_from = int(np.argmax(played.tracked))
    last = len(played) - tracked_from - 1
    assert len(worlds) > last
    sim = hb.simulate(
        REPO / "config" / "scenes" / "carl-lift.toml",
        hand=trace,
        hand_offset=OFFSET,
        frames=int(worlds.step[last]),
    )
    # Bit for bit: the world that answers the last sample is simulate --hand's.
    assert np.array_equal(worlds.position[last], sim.position)
    assert np.array_equal(worlds.rotation[last], sim.rotation)
    assert np.array_equal(worlds.mode[last], sim.mode)
    assert worlds.position[: last + 1, 0, 1].max() > 0.4  # it lifted the cube

    r = json.loads(report.read_text())
    assert r["budget"]["ok"], r["budget"]
    assert r["session"]["source"] == "external"
    assert r["devices"]["external"]["samples"] == len(played)
    assert r["devices"]["external"]["rejected_records"] == 4
    assert r["stages"]["external"]["final_report"]
    assert r["stages"]["external"]["origin_us"]["count"] == len(played)


def test_a_source_without_a_session_says_how_to_start_one(monkeypatch) -> None:
    monkeypatch.delenv("HANDBLOCKS_BUS", raising=False)
    try:
        hb.Source("nosuchsession1")
    except hb.SourceError as e:
        assert "kind = \"external\"" in str(e)
    else:
        raise AssertionError("a source without its session was opened")


def test_a_bad_command_is_refused_by_the_launcher(tmp_path: Path) -> None:
    file = session_file(tmp_path, [])
    child = launch(str(file), "--bus-id", bus_id("bad"))
    out, _ = child.communicate(timeout=60)
    assert child.returncode == 2, out
    assert "command" in out and "external" in out


def test_a_program_that_never_closes_its_source_still_ends_its_session(tmp_path: Path) -> None:
    script = tmp_path / "forgetful.py"
    script.write_text(
        "import sys, time\n"
        "import numpy as np\n"
        "import handblocks as hb\n"
        "joints = hb.Recording(sys.argv[1]).joints()\n"
        "source = hb.Source()  # no `with`, no close(): the end of the program closes it\n"
        "for i in range(60):\n"
        "    source.publish(int(joints.time_ns[i]), joints.position[i], joints.rotation[i],\n"
        "                   wrist_position=joints.wrist_position[i],\n"
        "                   wrist_rotation=joints.wrist_rotation[i])\n"
        "    time.sleep(0.01)\n"
    )
    bus = bus_id("forget")
    report = tmp_path / "report.json"
    child = launch(
        str(session_file(tmp_path, [sys.executable, str(script), str(carl("lift"))])),
        "--bus-id", bus, "--report", str(report), *CEILINGS,
    )
    finish(child, "the forgetful source's session")
    nothing_left(bus)
    r = json.loads(report.read_text())
    assert r["stages"]["external"]["final_report"] and not r["failures"], r["failures"]
    assert r["devices"]["external"]["samples"] == 60


def test_a_source_faster_than_its_limit_is_refused_and_the_session_drops_nothing(
    tmp_path: Path,
) -> None:
    """Issue 40: 20,000 hands published at 123,000 a second made a session drop a third of its
    worlds, and its budget said ok. A source now publishes at most hb's 240 hands a second (60
    at once): the rest are refused, counted as `rate` in counts() and by name in the report
    (`devices.external.refused`), and nothing downstream is dropped."""
    script = tmp_path / "flood.py"
    script.write_text(
        "import json, sys, warnings\n"
        "import numpy as np\n"
        "import handblocks as hb\n"
        "j = hb.Recording(sys.argv[1]).joints()\n"
        "offset = np.array([float(x) for x in sys.argv[2:5]])\n"
        "warnings.simplefilter('ignore')\n"
        "with hb.Source() as source:\n"
        "    for i in range(20000):\n"
        "        k = i % len(j)\n"
        "        source.publish((i + 1) * 8_333_333, j.position[k] + offset, j.rotation[k],\n"
        "                       wrist_position=j.wrist_position[k] + offset,\n"
        "                       wrist_rotation=j.wrist_rotation[k])\n"
        "    print('flood: ' + json.dumps(source.counts()), flush=True)\n"
        "    source.wait(0.5)\n"
    )
    bus = bus_id("flood")
    rec, report = tmp_path / "flood.mcap", tmp_path / "report.json"
    child = launch(
        str(
            session_file(
                tmp_path,
                [sys.executable, str(script), str(carl("lift"))] + [str(x) for x in OFFSET],
            )
        ),
        "--bus-id", bus, "--record", str(rec), "--report", str(report), *CEILINGS,
        "--set", "budget.max_dropped=0",
    )
    out = finish(child, "the flooding source's session")
    nothing_left(bus)
    line = next(l for l in out.splitlines() if l.startswith("flood: "))
    counts = json.loads(line[len("flood: "):])
    refused = counts["refused"]["rate"]
    assert refused > 0 and counts["published"] + refused == 20000, counts
    assert counts["published"] <= 60 + 240 * 10, counts  # the burst, then 240 a second

    r = json.loads(report.read_text())
    assert r["budget"]["ok"], r["budget"]
    device = r["devices"]["external"]
    assert device["samples"] == counts["published"], device
    assert device["refused"] == {"rate": refused}, device
    assert device["rejected_records"] == refused, device
    dropped = {t: f["dropped"] for t, f in r["topics"].items() if f["dropped"]}
    assert not dropped, dropped


def test_a_python_source_of_two_hands_drives_both(tmp_path: Path) -> None:
    """Issue 41: a tracker of two hands publishes each frame's right, then its left, with one
    time (``hand="left"``); the session takes both (docs/model.md "Two hands")."""
    trace = carl("lift")
    command = [sys.executable, str(Path(__file__).with_name("drive_two_hands.py")), str(trace)]
    command += [str(x) for x in OFFSET]
    bus = bus_id("two")
    rec = tmp_path / "two.mcap"
    child = launch(str(session_file(tmp_path, command)), "--bus-id", bus, "--record", str(rec),
                   *CEILINGS)
    out = finish(child, "the two-hand source's session")
    nothing_left(bus)
    assert "drive_two_hands: published" in out, out
    played = hb.Recording(trace).joints()
    recording = hb.Recording(rec)
    joints = recording.joints()
    assert len(joints) == 2 * len(played)
    assert np.array_equal(joints.side, np.tile([0, 1], len(played)))
    assert np.array_equal(joints.time_ns[0::2], joints.time_ns[1::2])
    hands = recording.hand()
    assert np.count_nonzero(hands.side == 1) == len(played)
    # The left hand is the right's 40 cm over, made apart by kinematics.
    right, left = hands.wrist_position[hands.side == 0], hands.wrist_position[hands.side == 1]
    assert np.allclose(left - right, [0.4, 0.0, 0.0])
