"""An external source for the tests: plays a CARL trace's joints through handblocks.Source,
in the trace's own time, moved by an offset; then tries two bad samples (NaN, and a time that
does not increase, a joint a kilometre away, a zero quaternion), which the source must refuse
and count.

Usage (as a session's [source] command): python drive_from_trace.py TRACE DX DY DZ
"""

import sys
import time
import warnings

import numpy as np

import handblocks as hb


def main() -> None:
    trace, offset = sys.argv[1], np.array([float(x) for x in sys.argv[2:5]])
    joints = hb.Recording(trace).joints()
    with hb.Source() as source:
        start = time.monotonic_ns()
        last = None
        for i in range(len(joints)):
            t = int(joints.time_ns[i])
            while time.monotonic_ns() - start < t:
                time.sleep(0.0005)
            if not source.running:
                break
            last = source.publish(
                t,
                joints.position[i] + offset,
                joints.rotation[i],
                bool(joints.tracked[i]),
                # CARL's joints 0 and 1 are identity poses; its wrist is given apart.
                wrist_position=joints.wrist_position[i] + offset,
                wrist_rotation=joints.wrist_rotation[i],
            )
            assert last is not None, f"sample {i} refused: {source.counts()}"
        end = int(joints.time_ns[-1])
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            nan = joints.position[-1].copy()
            nan[3, 1] = np.nan
            assert source.publish(end + 1_000_000, nan, joints.rotation[-1]) is None
            assert source.publish(end, joints.position[-1] + offset, joints.rotation[-1]) is None
            far = joints.position[-1] + offset
            far[5] = [0.0, 1e3, 0.0]  # a kilometre: millimetres given as metres, say
            assert source.publish(end + 2_000_000, far, joints.rotation[-1]) is None
            flat = joints.rotation[-1].copy()
            flat[7] = 0.0  # no rotation at all
            assert source.publish(end + 3_000_000, joints.position[-1] + offset, flat) is None
        assert [w.category for w in said] == [hb.SourceWarning] * 4, said
        assert "thumb_tip" in str(said[2].message) and "index_proximal" in str(said[3].message)
        counts = source.counts()
        assert counts["published"] == len(joints), counts
        assert counts["refused"] == {"not finite": 1, "too far": 1, "rotation norm": 1,
                                     "order": 1, "rate": 0}, counts
        print(f"drive_from_trace: published {counts['published']}, refused {counts['refused']}",
              flush=True)
        # Let the pipeline take the last hand before the session ends.
        source.wait(0.5)


if __name__ == "__main__":
    main()
