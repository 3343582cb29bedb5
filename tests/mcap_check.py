"""Reads a handblocks recording with the standard MCAP reader (the `mcap` Python package) and
prints what it found as JSON: per topic the schema, encodings and message count, and the seq of
every message (from the first 8 bytes of the sample, the Stamp's seq). Used by
tests/recording.rs to show that recordings open outside handblocks."""
import json
import struct
import sys

from mcap.reader import make_reader

with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
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
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        topics[channel.topic]["seqs"].append(struct.unpack_from("<Q", message.data)[0])
    print(json.dumps({"profile": header.profile, "chunks": len(summary.chunk_indexes), "topics": topics}))
