"""Reads a handblocks recording with the MCAP project's reference Python reader (`mcap`) and
decodes every message with its ROS 2 CDR decoder (`mcap-ros2-support`, as Foxglove decodes
them), knowing nothing of handblocks but the file; the `/scene` channel (foxglove.SceneUpdate,
what Foxglove's 3D panel draws) and `/tf` (foxglove.FrameTransforms, the hand's frames) with
its protobuf decoder (`mcap-protobuf-support`). Prints JSON: per topic the schema, encodings,
message count and every message's seq; the last world sample's step and block poses; the last
scene's world seq, entities, labels and poses; and the last /tf's log time and transforms.
Used by tests/recording.rs to show that recordings open in the standard tools."""
import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory(), ProtobufDecoderFactory()])
    header = reader.get_header()
    summary = reader.get_summary()
    topics = {}
    for channel_id, channel in summary.channels.items():
        schema = summary.schemas[channel.schema_id]
        topics[channel.topic] = {
            "schema": schema.name,
            "schema_encoding": schema.encoding,
            "message_encoding": channel.message_encoding,
            "layout": schema.data.decode() if schema.encoding == "ros2msg" else None,
            "statistics_count": summary.statistics.channel_message_counts.get(channel_id, 0),
            "seqs": [],
        }
    last_world = None
    last_scene = None
    last_tf = None
    for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
        if channel.topic == "/scene":
            topics[channel.topic]["seqs"].append(message.sequence)
            last_scene = (message.sequence, decoded)
            continue
        if channel.topic == "/tf":
            topics[channel.topic]["seqs"].append(message.sequence)
            last_tf = (message.sequence, message.log_time, decoded)
            continue
        topics[channel.topic]["seqs"].append(decoded.stamp.seq)
        if channel.topic == "/world":
            last_world = decoded
    world = {
        "seq": last_world.stamp.seq,
        "step": last_world.step,
        "grasped_block": last_world.grasped_block,
        "blocks": [
            {"position": list(b.pose.position), "rotation": list(b.pose.rotation), "mode": b.mode}
            for b in last_world.blocks[: last_world.block_count]
        ],
    }
    scene = None
    if last_scene is not None:
        seq, update = last_scene
        scene = {
            "world_seq": seq,
            "entities": [
                {
                    "id": e.id,
                    "frame_id": e.frame_id,
                    "texts": [t.text for t in e.texts],
                    "cubes": [[c.pose.position.x, c.pose.position.y, c.pose.position.z]
                              for c in e.cubes],
                    "lines": len(e.lines),
                }
                for e in update.entities
            ],
        }
    tf = None
    if last_tf is not None:
        seq, log_time, message = last_tf
        tf = {
            "world_seq": seq,
            "log_time": log_time,
            "transforms": [
                {
                    "parent": t.parent_frame_id,
                    "child": t.child_frame_id,
                    "stamp": t.timestamp.seconds * 1_000_000_000 + t.timestamp.nanos,
                    "translation": [t.translation.x, t.translation.y, t.translation.z],
                    "rotation": [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w],
                }
                for t in message.transforms
            ],
        }
    print(json.dumps({"profile": header.profile, "chunks": len(summary.chunk_indexes),
                      "topics": topics, "last_world": world, "last_scene": scene,
                      "last_tf": tf}))
