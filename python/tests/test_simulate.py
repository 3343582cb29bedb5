"""handblocks.simulate: the JSON of every scene equals `handblocks simulate --json`, byte for
byte; a dict scene is the file's scene, refused with the file's messages; a trace drives it as
`--hand` does."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import handblocks as hb
from conftest import REPO, carl, handblocks

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = None

SCENES = sorted((REPO / "config" / "scenes").glob("**/*.toml"))


def scene_id(p: Path) -> str:
    return str(p.relative_to(REPO / "config" / "scenes"))


@pytest.mark.parametrize("scene", SCENES, ids=scene_id)
def test_every_scene_equals_the_commands_json(scene: Path) -> None:
    done = handblocks("simulate", "--json", str(scene), check=False, timeout=900)
    if done.returncode == 2:
        # A scene the command refuses (config/scenes/hard holds some on purpose): refused
        # here with its message.
        with pytest.raises(hb.HandblocksError) as refused:
            hb.simulate(scene)
        assert str(refused.value) in done.stderr
        return
    assert done.returncode == 0, done.stderr
    cli = done.stdout
    sim = hb.simulate(scene)
    assert sim.to_json() == cli
    report = json.loads(cli)
    assert sim.frames == report["frames"]
    assert sim.names == [b["name"] for b in report["blocks"]]
    assert sim.position.tolist() == [b["position"] for b in report["blocks"]]
    assert sim.rotation.tolist() == [b["rotation"] for b in report["blocks"]]
    assert sim.modes == [b["mode"] for b in report["blocks"]]
    assert [(e.step, e.kind, e.block) for e in sim.events] == [
        (e["step"], e["kind"], e["block"]) for e in report["events"]
    ]


@pytest.mark.parametrize("name", ["grasp-throw", "tip"])
def test_the_precise_model_and_frames_as_the_command_takes_them(name: str) -> None:
    scene = REPO / "config" / "scenes" / f"{name}.toml"
    cli = handblocks("simulate", "--json", "--model", "precise", "--frames", "300", str(scene))
    assert hb.simulate(scene, model="precise", frames=300).to_json() == cli.stdout
    assert hb.simulate(name, frames=300).to_json() == handblocks(
        "simulate", "--json", "--frames", "300", name
    ).stdout


@pytest.mark.parametrize("name", ["lift", "push"])
def test_a_trace_drives_the_world_as_hand_does(name: str) -> None:
    scene = REPO / "config" / "scenes" / f"carl-{name}.toml"
    offset = "0,-1.45,0" if name == "push" else "0,-0.92,0"
    cli = handblocks(
        "simulate", "--json", "--hand", str(carl(name)), "--hand-offset", offset, str(scene)
    )
    sim = hb.simulate(
        scene, hand=carl(name), hand_offset=[float(x) for x in offset.split(",")]
    )
    assert sim.to_json() == cli.stdout


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
def test_a_dict_scene_is_the_files_scene() -> None:
    scene = REPO / "config" / "scenes" / "grasp-throw.toml"
    table = tomllib.loads(scene.read_text())
    assert hb.simulate(table).to_json() == hb.simulate(scene).to_json()
    # numpy values are taken as their Python values
    table["world"] = dict(table.get("world", {}), step_hz=np.float64(table.get("world", {}).get("step_hz", 60.0)))
    assert hb.simulate(table, frames=10).frames == 10


@pytest.mark.parametrize(
    "edit, key",
    [
        ({"world": {"step_hz": -3}}, "step_hz"),
        ({"world": {"model": "quantum"}}, "model"),
        ({"blocks_typo": 1}, "blocks_typo"),
    ],
)
def test_a_bad_dict_scene_is_refused_with_the_files_message(tmp_path: Path, edit: dict, key: str) -> None:
    base = {"block": [{"name": "a", "shape": "box", "size": [0.1, 0.1, 0.1], "position": [0.0, 0.05, 0.0]}]}
    scene = {**base, **edit}
    with pytest.raises(hb.SceneError) as refused:
        hb.simulate(scene)
    message = str(refused.value)
    assert message.startswith("<dict>") and key in message
    # The same scene as a file: the command's message, the file's name in place of <dict>.
    lines = []
    for table, values in scene.items():
        if isinstance(values, dict):
            lines.append(f"[{table}]")
            lines += [f"{k} = {json.dumps(v)}" for k, v in values.items()]
        elif isinstance(values, list):
            for item in values:
                lines.append(f"[[{table}]]")
                lines += [f"{k} = {json.dumps(v)}" for k, v in item.items()]
        else:
            lines.insert(0, f"{table} = {json.dumps(values)}")
    file = tmp_path / "scene.toml"
    file.write_text("\n".join(lines) + "\n")
    cli = handblocks("simulate", "--json", str(file), check=False)
    assert cli.returncode == 2
    assert message.replace("<dict>", str(file)) in cli.stderr


def test_wrong_arguments_say_what_is_allowed() -> None:
    scene = REPO / "config" / "scenes" / "grasp-throw.toml"
    with pytest.raises(ValueError, match="paper"):
        hb.simulate(scene, model="exact")
    with pytest.raises(hb.SceneError, match="nowhere.toml"):
        hb.simulate("nowhere.toml")
    with pytest.raises(hb.RecordingError, match="no-trace"):
        hb.simulate(scene, hand="/no-trace.carl")
    with pytest.raises(TypeError, match="scene"):
        hb.simulate(42)  # type: ignore[arg-type]


def run_python(code: str, timeout: float = 60) -> str:
    """Runs `code` in a Python of its own (a crash or a hang there fails this test instead of
    killing or blocking the test run); its stdout and stderr. Fails when it outlives
    `timeout` seconds."""
    try:
        done = subprocess.run(
            [sys.executable, "-c", textwrap.dedent(code)],
            capture_output=True,
            text=True,
            timeout=timeout,
            cwd=REPO,
        )
    except subprocess.TimeoutExpired as e:
        raise AssertionError(f"still running after {timeout} s: {e.stdout!r} {e.stderr!r}") from None
    return f"exit {done.returncode}\n{done.stdout}{done.stderr}"


REFUSED = """
    import handblocks as hb
    try:
        hb.simulate(scene)
        print("ran")
    except ValueError as e:
        print("ValueError:", e)
"""


def test_simulate_refuses_a_cyclic_dict_naming_the_key() -> None:
    out = run_python("scene = {'block': []}\nscene['world'] = scene\n" + textwrap.dedent(REFUSED))
    assert "exit 0" in out, out
    assert "ValueError: <dict>: key `world` holds the scene dict itself" in out, out


def test_simulate_refuses_a_list_that_contains_itself_naming_the_key() -> None:
    out = run_python(
        "loop = []\nloop.append(loop)\nscene = {'block': loop}\n" + textwrap.dedent(REFUSED)
    )
    assert "exit 0" in out, out
    assert "ValueError: <dict>: key `block[0]` holds the list at `block` again" in out, out
    # A cycle further down, through a list: named by its whole path.
    out = run_python(
        "scene = {'world': {'x': []}}\nscene['world']['x'].append(scene['world'])\n"
        + textwrap.dedent(REFUSED)
    )
    assert "ValueError: <dict>: key `world.x[0]` holds the dict at `world` again" in out, out


def test_simulate_refuses_a_dict_nested_30000_deep_naming_the_depth() -> None:
    out = run_python(
        "scene = {}\nat = scene\nfor _ in range(30000):\n    at['a'] = {}\n    at = at['a']\n"
        + textwrap.dedent(REFUSED)
    )
    assert "exit 0" in out, out
    assert "ValueError: <dict>: `a.a.a" in out and "nests deeper than 64" in out, out


def test_a_list_shared_by_two_blocks_is_no_cycle() -> None:
    size = [0.1, 0.1, 0.1]
    scene = {
        "block": [
            {"name": "a", "shape": "box", "size": size, "position": [0.0, 0.05, 0.0]},
            {"name": "b", "shape": "box", "size": size, "position": [0.5, 0.05, 0.0]},
        ]
    }
    assert hb.simulate(scene, frames=10).names == ["a", "b"]


def test_frames_beyond_its_bound_is_refused_stating_the_range() -> None:
    scene = REPO / "config" / "scenes" / "grasp-throw.toml"
    assert hb.MAX_FRAMES == 10_000_000
    for frames in [hb.MAX_FRAMES + 1, 10**9, 10**30, -1]:
        with pytest.raises(ValueError, match=f"frames={frames}: allowed: 0 to 10000000 steps"):
            hb.simulate(scene, frames=frames)
    with pytest.raises(TypeError, match="frames"):
        hb.simulate(scene, frames="10")  # type: ignore[arg-type]
    assert hb.simulate(scene, frames=np.int64(0)).frames == 0


def test_ctrl_c_stops_a_long_simulation() -> None:
    # The longest run allowed, of the field of 1024 blocks under the precise model (~7 ms a
    # step: most of a day): SIGINT after 2 s must end it with KeyboardInterrupt at once.
    out = run_python(
        f"""
        import os, signal, threading, time
        import handblocks as hb
        # Python's own Ctrl-C handler, whatever this process inherited (a shell's background
        # job starts with SIGINT ignored).
        signal.signal(signal.SIGINT, signal.default_int_handler)
        threading.Timer(2.0, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        start = time.monotonic()
        try:
            scene = {str(REPO / "config" / "scenes" / "field-1024.toml")!r}
            hb.simulate(scene, model="precise", frames=hb.MAX_FRAMES)
            print("finished")
        except KeyboardInterrupt:
            print(f"interrupted after {{time.monotonic() - start:.1f}} s")
        """,
        timeout=90,
    )
    assert "interrupted after" in out, out
    seconds = float(out.split("interrupted after ")[1].split(" s")[0])
    assert seconds < 30, out


def test_simulate_refuses_a_fifo_as_hand_or_scene_instead_of_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "lift.fifo"
    os.mkfifo(fifo)
    out = run_python(
        f"""
        import handblocks as hb
        try:
            hb.simulate("grasp-throw", hand={str(fifo)!r}, frames=10)
            print("RAN TO ITS END")
        except hb.RecordingError as e:
            print("RecordingError:", e)
        try:
            hb.simulate({str(fifo)!r}, frames=10)
            print("RAN TO ITS END")
        except hb.SceneError as e:
            print("SceneError:", e)
        """,
        timeout=30,
    )
    assert "RAN TO ITS END" not in out, out
    assert "RecordingError: " + str(fifo) in out, out
    assert "SceneError: " + str(fifo) in out, out
    assert out.count("it is a FIFO (named pipe), not a regular file") == 2, out


def test_both_hands_of_a_trace_drive_the_world_and_events_name_them() -> None:
    """Issue 41: ``hands="both"`` is ``simulate --hands both``: the events name the hand."""
    scene = REPO / "config" / "scenes" / "carl-lift.toml"
    both = hb.simulate(scene, hand=carl("lift"), hand_offset=(0.0, -0.92, 0.0), hands="both")
    one = hb.simulate(scene, hand=carl("lift"), hand_offset=(0.0, -0.92, 0.0))
    grasps = [e for e in both.events if e.kind == "grasp"]
    assert grasps and all(e.hand in ("right", "left") for e in grasps), both.events
    assert all(e.hand is None for e in one.events)
    with pytest.raises(ValueError, match="both"):
        hb.simulate(scene, hand=carl("lift"), hands="all")


@pytest.mark.skipif(tomllib is None, reason="tomllib is Python 3.11+")
def test_a_scene_of_two_scripted_hands_names_them_and_its_dict_is_the_file() -> None:
    """Issue 41: a scene's ``[left_hand]`` beside its ``[hand]``: the events name the hand, as
    from a file so from a dict; the precise model refuses the second hand naming the key."""
    scene = REPO / "config" / "scenes" / "two-hand-carry.toml"
    sim = hb.simulate(scene)
    held = [(e.kind, e.hand) for e in sim.events if e.kind in ("grasp", "release")]
    assert held == [("grasp", "right"), ("grasp", "left"), ("release", "right"), ("release", "left")]
    table = tomllib.loads(scene.read_text())
    assert hb.simulate(table).to_json() == sim.to_json()
    table["world"] = {"model": "precise"}
    with pytest.raises(hb.SceneError, match="left_hand"):
        hb.simulate(table)


def test_the_package_has_the_version_of_the_command() -> None:
    """Issue 43: ``handblocks.__version__``, the workspace's, as ``handblocks --version``."""
    out = handblocks("--version").stdout
    assert hb.__version__ and hb.__version__ in out, (hb.__version__, out)


def test_a_trajectory_holds_every_step_and_ends_where_the_run_ends() -> None:
    """Issue 43: ``simulate(..., trajectory=True)`` gives per-step arrays to plot; their last
    step is the final state, and without it the run is the same and has none."""
    plain = hb.simulate("tip", frames=240)
    s = hb.simulate("tip", frames=240, trajectory=True)
    blocks = len(s.names)
    assert s.path_position.shape == (240, blocks, 3)
    assert s.path_rotation.shape == (240, blocks, 4)
    assert s.path_mode.shape == (240, blocks)
    assert s.time.shape == (240,) and s.time[-1] == pytest.approx(240 / 120.0)
    np.testing.assert_array_equal(s.path_position[-1], s.position)
    np.testing.assert_array_equal(s.path_rotation[-1], s.rotation)
    np.testing.assert_array_equal(s.path_mode[-1], s.mode)
    assert s.to_json() == plain.to_json()
    assert plain.path_position is None and plain.time is None
