"""The columns a recording gives come from the topic table's field lists (common/src/topic.rs),
named by one rule (python/src/arrays.rs): each class of this package declares exactly those, with
the shapes and types the arrays have always had."""

from __future__ import annotations

import dataclasses

import numpy as np

import handblocks as hb
from conftest import carl

#: The class of each topic's samples.
CLASSES = {
    "world": hb.World,
    "hand": hb.Hand,
    "joints": hb.Joints,
    "glove": hb.Glove,
    "tracker": hb.Tracker,
    "frame": hb.Frame,
    "peer_hand": hb.PeerHand,
}


def test_every_class_declares_its_topics_columns() -> None:
    rec = hb.Recording(carl("lift"))
    assert set(CLASSES) == set(hb.TOPICS)
    for topic, cls in CLASSES.items():
        columns = rec._native.arrays(topic)
        declared = {
            f.name
            for f in dataclasses.fields(cls)
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        }
        assert set(columns) == declared, topic


def test_the_columns_keep_their_shapes_and_types() -> None:
    rec = hb.Recording(carl("lift"))
    joints = rec.joints()
    n = len(joints)
    assert n > 100
    assert joints.position.shape == (n, 26, 3) and joints.rotation.shape == (n, 26, 4)
    assert joints.wrist_position.shape == (n, 3) and joints.tracked.dtype == np.bool_
    assert joints.side.dtype == np.uint32 and joints.seq.dtype == np.uint64
    world = rec.world()
    assert world.position.shape == (0, 0, 3) and world.mode.shape == (0, 0)
    assert world.grasped_block.dtype == np.int32 and world.step.dtype == np.uint64
    hand = rec.hand()
    assert hand.finger_points.shape == (0, 5, 5, 3)
    assert hand.palm_vertices.shape == (0, 16, 3) and hand.finger_radius.shape == (0, 5)
    assert rec.glove().angles.shape == (0, 22)
    assert rec.frame().skipped_worlds.dtype == np.uint64
