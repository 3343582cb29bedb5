"""handblocks.simulate: the JSON of every scene equals `handblocks simulate --json`, byte for
byte; a dict scene is the file's scene, refused with the file's messages; a trace drives it as
`--hand` does."""

from __future__ import annotations

import json
import sys
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
