"""handblocks from Python: recordings as numpy arrays, the block world as a function, and a
live session to read and to drive.

- ``Recording(path)``: one of our MCAP recordings (every topic) or a CARL trace (its joints)
  as numpy arrays, one row per sample, with the samples' stamps as columns.
- ``simulate(scene, hand=None, model=None, frames=None)``: a scene's block world run to its
  end in this process; ``Simulation.to_json()`` is ``handblocks simulate --json`` byte for
  byte.
- ``Session(bus_id=None)``: a running session; ``subscribe("world")`` yields its samples as
  read-only numpy views of the publisher's shared memory (zero-copy).
- ``Source()``: this program as a session's ``external`` source: it publishes OpenXR hand
  joints, stamped, checked and counted as any source's.

The package is built from the project's own Rust crates (``handblocks._native``), so every
layout here is the one the processes use. Positions are metres, rotations quaternions
``[x, y, z, w]``, times nanoseconds; ``time_ns`` is a sample's time in its source's own
timeline, ``origin_ns`` and ``publish_ns`` are CLOCK_MONOTONIC (``monotonic_ns()``).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from typing import (
    Any,
    Dict,
    Iterator,
    List,
    Mapping,
    NamedTuple,
    Optional,
    Sequence,
    Tuple,
    Union,
)

import numpy as np
import numpy.typing as npt

from . import _native
from ._native import (
    HandblocksError,
    RecordingError,
    SceneError,
    SessionError,
    SimulateError,
    SourceError,
    MAX_FRAMES,
    TRACKING_HOLD_NS,
    monotonic_ns,
)

#: The block modes, by the value a ``mode`` array holds.
MODE_NAMES: Tuple[str, ...] = tuple(_native.MODE_NAMES)
#: OpenXR's 26 hand joints, in the order of every ``joints`` array.
JOINT_NAMES: Tuple[str, ...] = tuple(_native.JOINT_NAMES)
#: The topics a session publishes and a recording holds.
TOPICS: Tuple[str, ...] = tuple(_native.TOPICS)
#: This package's version (the handblocks workspace's).
__version__: str = _native.__version__

__all__ = [
    "Counts",
    "Recording",
    "World",
    "Hand",
    "Joints",
    "Glove",
    "Tracker",
    "Frame",
    "PeerHand",
    "simulate",
    "Simulation",
    "Event",
    "Session",
    "Subscription",
    "Sample",
    "Source",
    "RecordingWarning",
    "SourceWarning",
    "HandblocksError",
    "RecordingError",
    "SceneError",
    "SimulateError",
    "SessionError",
    "SourceError",
    "MODE_NAMES",
    "JOINT_NAMES",
    "TOPICS",
    "TRACKING_HOLD_NS",
    "MAX_FRAMES",
    "monotonic_ns",
]

PathLike = Union[str, "os.PathLike[str]"]
U64 = npt.NDArray[np.uint64]
U32 = npt.NDArray[np.uint32]
I32 = npt.NDArray[np.int32]
F64 = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]


class RecordingWarning(UserWarning):
    """A recording that is damaged: what comes before the damage was read."""


class SourceWarning(UserWarning):
    """Joints an external source refused (the first of each kind is said)."""


@dataclass(frozen=True)
class _Stamps:
    #: The sample's sequence number on its topic (gaps: samples the recorder never got).
    seq: U64
    #: The sample's time in its source's own timeline (a world: of the hand it stepped to).
    time_ns: U64
    #: CLOCK_MONOTONIC when the source sample entered the pipeline.
    origin_ns: U64
    #: CLOCK_MONOTONIC when this sample was published.
    publish_ns: U64

    def __len__(self) -> int:
        return int(self.seq.shape[0])


@dataclass(frozen=True)
class World(_Stamps):
    """The blocks after each step: ``position (n, blocks, 3)``, ``rotation (n, blocks, 4)``,
    ``mode (n, blocks)`` (an index into ``mode_names``), and the step's hand."""

    step: U64
    hand_seq: U64
    #: The grasped block's index, or -1.
    grasped_block: I32
    position: F64
    rotation: F64
    mode: U32
    finger_count: U32
    finger_point_count: U32
    #: The fingers' check points as the stepper used them, ``(n, 5, 5, 3)``.
    finger_points: F64
    #: The blocks' names (from the recording, else ``block0``, ``block1``, ...).
    names: List[str] = field(default_factory=list)
    mode_names: Tuple[str, ...] = MODE_NAMES

    def modes(self, block: Union[int, str]) -> List[str]:
        """One block's mode at each step, by name."""
        b = self.names.index(block) if isinstance(block, str) else block
        return [self.mode_names[m] for m in self.mode[:, b]]


@dataclass(frozen=True)
class Hand(_Stamps):
    """The hand model: wrist, fingers' check points, palm. ``side``: 0 the right hand (or a
    one-hand session's only hand), 1 the left of a two-hand session. ``participant``: whose
    hand in a shared world (0 the first to join; always 0 elsewhere)."""

    tracked: Bools
    side: U32
    participant: U32
    wrist_position: F64
    wrist_rotation: F64
    finger_count: U32
    finger_point_count: U32
    finger_points: F64
    finger_radius: F64
    palm_vertex_count: U32
    palm_vertices: F64


@dataclass(frozen=True)
class Joints(_Stamps):
    """OpenXR hand joints: ``position (n, 26, 3)``, ``rotation (n, 26, 4)`` in the order of
    ``joint_names``. ``side``: 0 the right hand (or a one-hand source's only hand), 1 the left
    of a two-hand source."""

    tracked: Bools
    side: U32
    wrist_position: F64
    wrist_rotation: F64
    position: F64
    rotation: F64
    joint_names: Tuple[str, ...] = tuple(JOINT_NAMES)


@dataclass(frozen=True)
class Glove(_Stamps):
    """Data-glove joint angles, radians, CyberGlove sensor order (``sensor_count`` used).
    ``side``: 0 the right hand's glove, 1 the left's (a scene of two scripted hands)."""

    sensor_count: U32
    side: U32
    angles: F64


@dataclass(frozen=True)
class Tracker(_Stamps):
    """The 6-DoF tracker's wrist pose. ``side``: 0 the right hand's, 1 the left's."""

    station: U32
    side: U32
    wrist_position: F64
    wrist_rotation: F64


@dataclass(frozen=True)
class Frame(_Stamps):
    """One drawn frame's timing."""

    world_seq: U64
    render_ns: U64
    origin_to_photon_ns: U64
    skipped_worlds: U64


@dataclass(frozen=True)
class PeerHand(_Stamps):
    """Another participant's hand in a shared world, as a participant's recording holds it
    (its own hands are in ``hand()``): the columns of ``Hand`` prefixed ``hand_``
    (``hand_participant`` the host's number for it, ``hand_finger_points (n, 5, 5, 3)``), and
    ``own_participant``, the number the host gave the recording's own participant. The stamp
    is the participant's machine's: when the hand arrived there."""

    own_participant: U32
    hand_tracked: Bools
    hand_side: U32
    hand_participant: U32
    hand_wrist_position: F64
    hand_wrist_rotation: F64
    hand_finger_count: U32
    hand_finger_point_count: U32
    hand_finger_points: F64
    hand_finger_radius: F64
    hand_palm_vertex_count: U32
    hand_palm_vertices: F64


class Recording:
    """One of our MCAP recordings, or a CARL trace, read into memory.

    A file that cannot be read raises ``RecordingError`` with ``handblocks inspect``'s
    message; a damaged one (cut off, a bad chunk) is read up to the damage, with a
    ``RecordingWarning`` and the damage in ``damage``, as ``inspect`` reads it.

    >>> rec = Recording("out/live.mcap")
    >>> w = rec.world()
    >>> w.position.shape            # (samples, blocks, 3)
    """

    def __init__(self, path: PathLike) -> None:
        self._native = _native.NativeRecording(os.fspath(path))
        if self._native.damage is not None:
            warnings.warn(
                f"{self._native.damage}", RecordingWarning, stacklevel=2
            )

    @property
    def path(self) -> str:
        return self._native.path

    @property
    def kind(self) -> str:
        """``"mcap"`` or ``"carl"``."""
        return self._native.kind

    @property
    def complete(self) -> bool:
        """True when the file was whole (closed properly, or read to its last byte)."""
        return self._native.complete

    @property
    def damage(self) -> Optional[str]:
        """Where and why reading stopped early; None for a whole file."""
        return self._native.damage

    @property
    def metadata(self) -> Dict[str, str]:
        """The recording's ``handblocks`` metadata: ``session``, ``scene``, ``source``,
        ``blocks``, ``unix_offset_ns``."""
        return self._native.metadata

    @property
    def session(self) -> Optional[str]:
        return self.metadata.get("session")

    @property
    def scene(self) -> Optional[str]:
        return self.metadata.get("scene")

    @property
    def segments(self) -> List[str]:
        """Files a restarted recorder went on in (each is a recording of its own)."""
        return self._native.segments

    def topics(self) -> Dict[str, Dict[str, Any]]:
        """Per topic: ``messages``, ``gaps``, ``seconds``, ``rate_hz``, ``schema``, ``bytes``,
        ``bytes_per_element``: ``handblocks inspect --json``'s figures."""
        return self._native.topics()

    def names(self, blocks: int) -> List[str]:
        """The blocks' names: as the recording lists them; for a recording made before it
        listed them, from the scene file it names, when that file is still there and names
        as many blocks; else ``block0``, ``block1``, ... (a scene's own default names)."""
        listed = self.metadata.get("blocks")
        if listed is not None:
            names = listed.split("\n")
            if len(names) == blocks:
                return names
        scene = self.scene
        if scene and os.path.isfile(scene):
            try:
                import tomllib  # Python 3.11+

                with open(scene, "rb") as f:
                    tables = tomllib.load(f).get("block", [])
                names = [t.get("name", f"block{i}") for i, t in enumerate(tables)]
                if len(names) == blocks and all(isinstance(n, str) for n in names):
                    return names
            except (ImportError, OSError, ValueError, AttributeError):
                pass
        return [f"block{i}" for i in range(blocks)]

    def world(self) -> World:
        d = self._native.arrays("world")
        return World(**d, names=self.names(d["position"].shape[1]))

    def hand(self) -> Hand:
        return Hand(**self._native.arrays("hand"))

    def joints(self) -> Joints:
        return Joints(**self._native.arrays("joints"))

    def glove(self) -> Glove:
        return Glove(**self._native.arrays("glove"))

    def tracker(self) -> Tracker:
        return Tracker(**self._native.arrays("tracker"))

    def frame(self) -> Frame:
        return Frame(**self._native.arrays("frame"))

    def peer_hand(self) -> PeerHand:
        return PeerHand(**self._native.arrays("peer_hand"))

    def __repr__(self) -> str:
        counts = ", ".join(
            f"{t} {v['messages']}" for t, v in self.topics().items() if v["messages"]
        )
        state = "complete" if self.complete else "damaged"
        return f"<handblocks.Recording {self.path!r} ({self.kind}, {state}): {counts}>"


@dataclass(frozen=True)
class Event:
    """A world event: ``kind`` (impact, rest, push, grasp, release, ...) of ``block`` at
    ``step``; ``hand``: in a two-hand world, the hand a grasp, release or push is by
    (``"right"`` or ``"left"``), else None; ``participant``: in a shared world, whose hand
    (0 the first to join; always 0 elsewhere)."""

    step: int
    kind: str
    block: str
    hand: Optional[str] = None
    participant: int = 0


@dataclass(frozen=True)
class Simulation:
    """What ``simulate`` returns: each block's final state, and the events."""

    frames: int
    names: List[str]
    #: ``(blocks, 3)`` metres: each block's G after the last step.
    position: F64
    #: ``(blocks, 4)`` quaternions ``[x, y, z, w]``.
    rotation: F64
    #: ``(blocks,)`` indices into ``MODE_NAMES``.
    mode: U32
    events: List[Event]
    clock_jumps: int
    refused_hands: int
    #: What the run said on the way (why this many steps, a trace's warnings).
    notes: List[str]
    #: With ``trajectory=True``: ``(steps, blocks, 3)`` every block's G after every step,
    #: ``(steps, blocks, 4)`` its quaternion, ``(steps, blocks)`` its mode, and ``time``
    #: ``(steps,)`` seconds of world time (step k ends at (k + 1) / step rate). None otherwise.
    path_position: Optional[F64] = None
    path_rotation: Optional[F64] = None
    path_mode: Optional[U32] = None
    time: Optional[F64] = None
    _json: str = field(repr=False, default="")
    _text: str = field(repr=False, default="")

    @property
    def modes(self) -> List[str]:
        return [MODE_NAMES[m] for m in self.mode]

    def to_json(self) -> str:
        """``handblocks simulate --json``'s output, byte for byte (its trailing newline
        included)."""
        return self._json

    def to_text(self) -> str:
        """``handblocks simulate``'s text."""
        return self._text


def simulate(
    scene: Union[PathLike, Mapping[str, Any]],
    hand: Optional[PathLike] = None,
    model: Optional[str] = None,
    frames: Optional[int] = None,
    hand_offset: Sequence[float] = (0.0, 0.0, 0.0),
    hands: str = "right",
    trajectory: bool = False,
) -> Simulation:
    """Runs a scene's block world to its end in this process, deterministically: what
    ``handblocks simulate SCENE [--hand TRACE] [--model M] [--frames N] --json`` prints.

    ``scene``: a scene file, a bare name (``"grasp-throw"``, looked up in
    ``$HANDBLOCKS_CONFIG/scenes`` or ``./config/scenes``), or a dict of the scene file's
    tables (checked as the file would be; errors name ``<dict>``). ``hand``: one of our
    recordings or a CARL trace in place of the scene's ``[hand]``, moved by ``hand_offset``
    metres; ``hands``: which of the trace's hands drive the world, ``"right"``, ``"left"`` or
    ``"both"`` (a CARL trace holds both; docs/model.md "Two hands"). ``model``: ``"paper"``,
    ``"precise"``, or None for the scene's ``[world] model``.
    ``frames``: steps in all, 0 to ``MAX_FRAMES`` (ten million: a day of world time at the
    default 120 steps a second); None: the hand's end plus time to settle.
    ``trajectory``: keep every block's pose and mode after every step, as arrays to plot
    (``path_position``, ``path_rotation``, ``path_mode``, ``time``; 64 bytes a block a step).

    The run lets other Python threads go on, and Ctrl-C stops it (``KeyboardInterrupt``,
    looked for every 50 ms).

    Raises ``SceneError`` (a scene refused: file, key, allowed range), ``RecordingError``
    (a trace that cannot be read: also a FIFO, a device or a folder given as ``hand``),
    ``SimulateError``, or ``ValueError`` (``frames`` out of range; a scene dict that contains
    itself, or nests deeper than 64 dicts and lists: the message names the key).
    """
    if hand is not None:
        hand = os.fspath(hand)
    if not isinstance(scene, Mapping):
        try:
            scene = os.fspath(scene)
        except TypeError:
            raise TypeError(
                f"scene: a path (str or os.PathLike) or a dict of the scene file's tables, "
                f"not {type(scene).__name__}"
            ) from None
    elif not isinstance(scene, dict):
        # Not copied when it is a dict already: a key that refers back to the scene is then
        # named as the scene itself (`world`), not as the copy's `world.world`.
        scene = dict(scene)
    offset = tuple(float(x) for x in hand_offset)
    if len(offset) != 3:
        raise ValueError(f"hand_offset: 3 numbers (metres), not {len(offset)}")
    d = _native.simulate(scene, hand, model, frames, offset, str(hands), bool(trajectory))
    path = {}
    if "path_position" in d:
        steps = d["path_mode"].shape[0]
        path = dict(
            path_position=d["path_position"],
            path_rotation=d["path_rotation"],
            path_mode=d["path_mode"],
            time=(np.arange(steps, dtype=np.float64) + 1.0) / d["step_hz"],
        )
    return Simulation(
        frames=d["frames"],
        names=d["names"],
        position=d["position"],
        rotation=d["rotation"],
        mode=d["mode"],
        events=[Event(**e) for e in d["events"]],
        clock_jumps=d["clock_jumps"],
        refused_hands=d["refused_hands"],
        notes=d["notes"],
        **path,
        _json=d["json"],
        _text=d["text"],
    )


#: One live sample (``Subscription`` yields them): its stamp as attributes (``seq``,
#: ``time_ns``, ``origin_ns``, ``publish_ns``, and ``received_ns``: when this reader took it),
#: its fields as read-only numpy views of the publisher's shared memory (``fields()``, or by
#: name: ``sample.position``), and ``copy()`` for arrays of your own.
Sample = _native.LiveSample


class Subscription:
    """One reader of one topic of a running session. Iterating yields each sample as it
    arrives, until the session ends; each is the publisher's shared memory itself: its fields
    are read-only numpy views (``sample.position``, ``sample.fields()``), valid while the
    sample or a view of it is alive. Keep what you need with ``sample.copy()``: a reader may
    hold only a few samples at once (the rest are its buffer).

    A slow reader costs the session nothing: the publisher overwrites its oldest unread
    sample, and ``counts()`` says how many were missed.
    """

    def __init__(self, native: Any, topic: str) -> None:
        self._native = native
        self.topic = topic

    def receive(self, timeout: Optional[float] = None) -> Optional[Sample]:
        """The next sample, waiting at most ``timeout`` seconds (None: until the session
        ends); None when none came."""
        return self._native.receive(timeout)

    def __iter__(self) -> Iterator[Sample]:
        return iter(self._native)

    def counts(self) -> "Counts":
        """Samples received, and samples missed (overwritten before this reader took them):
        ``counts().received``, ``counts().missed`` (a tuple too: ``received, missed = ...``)."""
        return Counts(*self._native.counts())


class Counts(NamedTuple):
    """A reader's counts (``Subscription.counts()``)."""

    #: Samples this reader received.
    received: int
    #: Samples it missed: the publisher overwrote them before this reader took them.
    missed: int


class Session:
    """A session running on this machine (``handblocks sessions`` lists them): ``bus_id`` names
    one, or None takes the only one running.

    >>> s = Session()
    >>> for w in s.subscribe("world"):
    ...     print(w.seq, w.position[0])
    """

    def __init__(self, bus_id: Optional[str] = None) -> None:
        self._native = _native.NativeSession(bus_id)

    @property
    def id(self) -> str:
        return self._native.id

    @property
    def session_file(self) -> str:
        return self._native.session_file

    @property
    def source(self) -> str:
        """Its source's kind: ``scripted``, ``devices``, ``replay``, ``remote``, ``webxr`` or
        ``external``."""
        return self._native.source

    @property
    def lossless(self) -> bool:
        return self._native.lossless

    @property
    def world_blocks(self) -> int:
        return self._native.world_blocks

    def is_running(self) -> bool:
        return self._native.is_running()

    def processes(self) -> List[Tuple[str, int]]:
        """The processes attached to its bus: (name, pid)."""
        return self._native.processes()

    def topics(self) -> Dict[str, Dict[str, int]]:
        """Per topic: publishers and subscribers attached now."""
        return self._native.topics()

    def subscribe(self, topic: str) -> Subscription:
        """A reader of ``topic`` (one of ``TOPICS``)."""
        return Subscription(self._native.subscribe(topic), topic)

    def __repr__(self) -> str:
        return f"<handblocks.Session {self.id} running {self.session_file}>"


class Source:
    """This program as its session's ``external`` source. The session file names it:

    .. code-block:: toml

        [source]
        kind = "external"
        command = ["python3", "my_tracker.py"]

    and ``handblocks launch`` starts it with the session's bus in ``$HANDBLOCKS_BUS``. Each
    ``publish`` sends one hand (OpenXR's 26 joints, ``JOINT_NAMES``) at ``time_ns`` in this
    program's own timeline: stamped, checked and counted as any source's sample. The session
    ends when the source closes (the end of its ``with`` block, ``close()``, or the program's
    end, which closes it too); ``running`` turns False when
    the session asks it to stop. Publish, or look at ``running``, at least once a second:
    each sends the latency report when it is due, and a source silent for 3 s is taken as
    stalled.

    >>> with Source() as src:
    ...     while src.running:
    ...         src.publish(t_ns, position, rotation)
    """

    def __init__(self, bus_id: Optional[str] = None) -> None:
        self._native = _native.NativeSource(bus_id)

    @property
    def bus_id(self) -> str:
        return self._native.bus_id

    @property
    def running(self) -> bool:
        return self._native.running

    def publish(
        self,
        time_ns: int,
        position: npt.ArrayLike,
        rotation: npt.ArrayLike,
        tracked: bool = True,
        wrist_position: Optional[npt.ArrayLike] = None,
        wrist_rotation: Optional[npt.ArrayLike] = None,
        hand: str = "right",
    ) -> Optional[int]:
        """Publishes one hand: ``position (26, 3)`` metres, ``rotation (26, 4)`` quaternions
        ``[x, y, z, w]``, at ``time_ns`` (increasing, for each hand). The wrist is joint 1
        (OpenXR's wrist) unless ``wrist_position (3,)`` and ``wrist_rotation (4,)`` give it apart.
        ``hand``: ``"right"`` (a one-hand tracker's only hand, whichever it is) or ``"left"``:
        a tracker of two hands publishes, for each frame, the right and then the left with the
        same ``time_ns`` (a lost one with ``tracked=False``), and the world takes both
        (docs/model.md "Two hands").
        ``tracked=False``: the hand is lost (its last pose is held for ``TRACKING_HOLD_NS``,
        then let go). Returns the sample's seq, or None when it was refused (not finite,
        farther than 100 m, a quaternion's norm outside 0.5-2, a time not after the last, or
        faster than 240 hands a second (a burst of 60 allowed): ``rate``, so a runaway loop
        cannot flood the session): counted in ``counts()`` and the session's report, and the
        first of each kind said as a ``SourceWarning``."""
        f64 = np.float64
        seq, warning = self._native.publish(
            int(time_ns),
            np.ascontiguousarray(position, dtype=f64),
            np.ascontiguousarray(rotation, dtype=f64),
            bool(tracked),
            None if wrist_position is None else np.ascontiguousarray(wrist_position, dtype=f64),
            None if wrist_rotation is None else np.ascontiguousarray(wrist_rotation, dtype=f64),
            str(hand),
        )
        if warning is not None:
            warnings.warn(f"refused: {warning}", SourceWarning, stacklevel=2)
        return seq

    def wait(self, seconds: float) -> bool:
        """Sleeps up to ``seconds`` while keeping the session's reports going; returns
        ``running``."""
        import time

        end = time.monotonic() + seconds
        while self.running and time.monotonic() < end:
            time.sleep(min(0.1, max(0.0, end - time.monotonic())))
        return self.running

    def counts(self) -> Dict[str, Any]:
        """``published``, ``refused`` by reason, and ``first_refused``."""
        return self._native.counts()

    def close(self) -> None:
        """Sends the final report; the session then ends. Idempotent."""
        self._native.close()

    def __enter__(self) -> "Source":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
