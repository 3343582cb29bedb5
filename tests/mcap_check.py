"""Reads a handblocks recording with the MCAP project's reference Python reader (`mcap`) and
decodes every message with its ROS 2 CDR decoder (`mcap-ros2-support`, as Foxglove decodes
them), knowing nothing of handblocks but the file. Prints JSON: per topic the schema, encodings,
message count and every message's seq; and the last world sample's step and block poses.
Used by tests/recording.rs to show that recordings open in the standard tools."""
import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    header = reader.get_header()
    summary = reader.get_summary()
    topics = {}
    for channel_id, channel in summary.channels.items():
        schema = summary.schemas[channel.schema_id]
        topics[channel.topic] = {
            "schema": schema.name,
            "schema_encoding": schema.encoding,
            "message_encoding": channel.message_encoding,
            "layout": schema.data.decode(),
            "statistics_count": summary.statistics.channel_message_counts.get(channel_id, 0),
            "seqs": [],
        }
    last_world = None
    for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
        topics[channel.topic]["seqs"].append(decoded.stamp.seq)
        if channel.topic == "world":
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
    print(json.dumps({"profile": header.profile, "chunks": len(summary.chunk_indexes),
                      "topics": topics, "last_world": world}))
