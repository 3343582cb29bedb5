"""Block heights over time from a recording, with matplotlib.

Each block's height (the y of its centre of mass G) against the recording's time, with the
stretches in which it was grasped shaded and its landings marked: what a block did, at a
glance. The recording is one of ours (`handblocks launch ... --record FILE`).

Usage:
    python examples/python/plot_recording.py RECORDING.mcap [--out heights.png]

Needs: pip install ./python matplotlib
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import handblocks as hb


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", help="one of our MCAP recordings")
    parser.add_argument("--out", help="write the plot to this PNG instead of showing it")
    args = parser.parse_args()

    import matplotlib

    if args.out:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    try:
        rec = hb.Recording(args.recording)
    except hb.RecordingError as e:
        print(f"plot_recording: {e}", file=sys.stderr)
        return 2
    world = rec.world()
    if len(world) == 0:
        print(f"plot_recording: {args.recording} holds no world (record a session with a "
              "stepper)", file=sys.stderr)
        return 2

    seconds = (world.time_ns - world.time_ns[0]) / 1e9
    grasped = hb.MODE_NAMES.index("grasped")
    fig, ax = plt.subplots(figsize=(9, 4.5), dpi=110)
    for b, name in enumerate(world.names):
        height = world.position[:, b, 1]
        (line,) = ax.plot(seconds, height, label=name, linewidth=1.6)
        held = world.mode[:, b] == grasped
        ax.fill_between(seconds, 0, height, where=held, color=line.get_color(), alpha=0.15,
                        step="mid", linewidth=0)
    ax.set_xlabel("time (s, the source's own)")
    ax.set_ylabel("height of G (m)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    title = rec.scene.rsplit("/", 1)[-1] if rec.scene else args.recording
    ax.set_title(f"block heights: {title} (shaded: grasped)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.tight_layout()
    if args.out:
        fig.savefig(args.out)
        print(f"plot_recording: {len(world)} worlds of {len(world.names)} block(s) -> {args.out}")
    else:
        plt.show()
    return 0


if __name__ == "__main__":
    sys.exit(main())
