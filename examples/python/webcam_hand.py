"""A webcam hand tracker (MediaPipe Hands) as a handblocks session's `external` source.

Each camera frame, MediaPipe finds the hand's 21 landmarks; this program makes them OpenXR's
26 joints (handblocks.JOINT_NAMES), places the hand in the scene, and publishes it with the
frame's time through handblocks.Source. The session's kinematics, stepper, renderer and
recorder take it from there, exactly as they take a glove's or a headset's hand.

Run it as its session's source (from the repository's root):

    pip install ./python mediapipe opencv-python
    handblocks launch config/sessions/webcam.toml

The launcher starts this program with the session's bus in $HANDBLOCKS_BUS and stops it with
the session (Ctrl-C at the launcher, or --duration). It is documented, not run in CI (no
camera there).

Where the hand goes. MediaPipe's world landmarks give the hand's shape in metres, about its
own centre; where the hand is comes from the image: the wrist's place in the frame sets x and
y over a workspace of --width by --height metres above the floor, and the hand's apparent size
sets its depth (a hand twice as big as at --reach is --depth-gain metres nearer the screen).
Axes: the camera faces you and you face the scene, so moving your hand toward the screen moves
it into the scene (-z), and the image is mirrored so your right is the scene's +x.
"""

from __future__ import annotations

import argparse
import sys
import time

try:
    import numpy as np

    import handblocks as hb
except ImportError as e:  # run by the launcher with whatever `python3` is on the PATH
    sys.exit(f"webcam_hand: {e.name} is missing from {sys.executable}: pip install ./python "
             "mediapipe opencv-python (or name your venv's python in [source] command)")

# MediaPipe's 21 landmarks: 0 wrist; thumb 1-4 (CMC, MCP, IP, tip); index 5-8 (MCP, PIP, DIP,
# tip); middle 9-12; ring 13-16; little 17-20.
# OpenXR's 26 joints from them: (the landmark, or two to average).
OPENXR_FROM_MEDIAPIPE = [
    (0, 9),   # palm: between the wrist and the middle knuckle
    (0,),     # wrist
    (1,), (2,), (3,), (4,),                 # thumb: metacarpal, proximal, distal, tip
    (0, 5), (5,), (6,), (7,), (8,),         # index: metacarpal (half-way), proximal, ... tip
    (0, 9), (9,), (10,), (11,), (12,),      # middle
    (0, 13), (13,), (14,), (15,), (16,),    # ring
    (0, 17), (17,), (18,), (19,), (20,),    # little
]
assert len(OPENXR_FROM_MEDIAPIPE) == len(hb.JOINT_NAMES)


def quaternion(m: np.ndarray) -> np.ndarray:
    """A rotation matrix's quaternion [x, y, z, w]."""
    t = np.trace(m)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) * 2
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
        q[i] = s / 4
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
    q = np.array(q)
    return q / np.linalg.norm(q)


def wrist_frame(points: np.ndarray, right: bool) -> np.ndarray:
    """The wrist's frame in the world (OpenXR's: fingers along -z, the back of the hand +y),
    as a rotation matrix whose columns are its x, y, z axes."""
    forward = points[12] - points[1]            # wrist -> middle knuckle: -z
    across = points[7] - points[22]             # little knuckle -> index knuckle
    z = -forward / np.linalg.norm(forward)
    back = np.cross(forward, across) if right else np.cross(across, forward)
    y = back - np.dot(back, z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return np.column_stack([x, y, z])


def to_joints(world_landmarks: np.ndarray, image_wrist: np.ndarray, hand_size: float,
              args: argparse.Namespace, right: bool) -> tuple:
    """MediaPipe's landmarks (metres, camera axes) -> OpenXR joints in the scene."""
    # Camera axes (x right in the image, y down, z away from the camera) -> the scene's
    # (mirrored x, y up, z toward you): into the screen is toward the camera, -z.
    shape = world_landmarks * np.array([-1.0, -1.0, 1.0])
    shape = shape - shape[0]
    u, v = image_wrist
    depth = args.depth_gain * (hand_size / args.reach - 1.0)
    wrist = np.array([
        (0.5 - u) * args.width,
        args.floor + (1.0 - v) * args.height,
        args.z - depth,
    ])
    points = np.array([shape[list(ix)].mean(axis=0) for ix in OPENXR_FROM_MEDIAPIPE]) + wrist
    frame = wrist_frame(points, right)
    rotation = np.tile(quaternion(frame), (len(points), 1))
    return points, rotation


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--camera", type=int, default=0, help="the camera's index (OpenCV)")
    parser.add_argument("--hand", choices=["right", "left"], default="right")
    parser.add_argument("--width", type=float, default=0.6, help="workspace width, m")
    parser.add_argument("--height", type=float, default=0.4, help="workspace height, m")
    parser.add_argument("--floor", type=float, default=0.02, help="lowest wrist height, m")
    parser.add_argument("--z", type=float, default=0.15, help="the wrist's z at --reach, m")
    parser.add_argument("--reach", type=float, default=0.25,
                        help="the hand's size in the image (wrist to middle knuckle, as a "
                             "fraction of the frame's height) at depth --z")
    parser.add_argument("--depth-gain", type=float, default=0.3,
                        help="metres nearer the screen when the hand looks twice as big")
    args = parser.parse_args()

    try:
        import cv2
        import mediapipe as mp
    except ImportError as e:
        print(f"webcam_hand: {e.name} is missing: pip install mediapipe opencv-python",
              file=sys.stderr)
        return 2
    camera = cv2.VideoCapture(args.camera)
    if not camera.isOpened():
        print(f"webcam_hand: cannot open camera {args.camera} (--camera N)", file=sys.stderr)
        return 2
    hands = mp.solutions.hands.Hands(max_num_hands=2, model_complexity=1,
                                     min_detection_confidence=0.6, min_tracking_confidence=0.5)
    want_right = args.hand == "right"
    last = None
    with hb.Source() as source:
        print(f"webcam_hand: camera {args.camera} drives session {source.bus_id}", flush=True)
        while source.running:
            ok, image = camera.read()
            t_ns = time.monotonic_ns()  # the frame's time, in this program's timeline
            if not ok:
                source.wait(0.01)
                continue
            found = hands.process(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
            chosen = None
            for landmarks, world, handed in zip(found.multi_hand_landmarks or [],
                                                found.multi_hand_world_landmarks or [],
                                                found.multi_handedness or []):
                # MediaPipe labels hands as seen in a mirrored (selfie) image.
                is_right = handed.classification[0].label == "Left"
                if is_right == want_right:
                    chosen = (landmarks, world)
                    break
            if chosen is None:
                if last is not None:
                    # Lost: the last pose, untracked (held for TRACKING_HOLD_NS, then let go).
                    source.publish(t_ns, last[0], last[1], tracked=False)
                continue
            landmarks, world = chosen
            image_points = np.array([[p.x, p.y] for p in landmarks.landmark])
            world_points = np.array([[p.x, p.y, p.z] for p in world.landmark])
            size = float(np.linalg.norm(image_points[9] - image_points[0]))
            position, rotation = to_joints(world_points, image_points[0], size, args, want_right)
            if source.publish(t_ns, position, rotation) is not None:
                last = (position, rotation)
    camera.release()
    counts = source.counts()
    print(f"webcam_hand: published {counts['published']}, refused {counts['refused']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
