"""An external source of two hands for the tests: plays a CARL trace's joints as the right hand
and the same joints 40 cm to the right as the left, each frame's right then left with the same
time, in the trace's own time, moved by an offset; then tries a hand that is neither.

Usage (as a session's [source] command): python drive_two_hands.py TRACE DX DY DZ
"""

import sys
import time

import numpy as np

import handblocks as hb


def main() -> None:
    trace, offset = sys.argv[1], np.array([float(x) for x in sys.argv[2:5]])
    joints = hb.Recording(trace).joints()
    beside = offset + np.array([0.4, 0.0, 0.0])
    with hb.Source() as source:
        start = time.monotonic_ns()
        for i in range(len(joints)):
            t = int(joints.time_ns[i])
            while time.monotonic_ns() - start < t:
                time.sleep(0.0005)
            if not source.running:
                break
            for hand, moved in (("right", offset), ("left", beside)):
                seq = source.publish(
                    t,
                    joints.position[i] + moved,
                    joints.rotation[i],
                    bool(joints.tracked[i]),
                    wrist_position=joints.wrist_position[i] + moved,
                    wrist_rotation=joints.wrist_rotation[i],
                    hand=hand,
                )
                assert seq is not None, f"sample {i} {hand} refused: {source.counts()}"
        try:
            source.publish(0, joints.position[0], joints.rotation[0], hand="middle")
            raise AssertionError("hand='middle' was taken")
        except ValueError as e:
            assert "right" in str(e) and "left" in str(e), e
        counts = source.counts()
        assert counts["published"] == 2 * len(joints), counts
        print(f"drive_two_hands: published {counts['published']}", flush=True)
        source.wait(0.5)


if __name__ == "__main__":
    main()
