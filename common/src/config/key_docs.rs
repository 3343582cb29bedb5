//! Each configuration key's line in the key catalog ([`super::catalog`], docs/config.md): what
//! it does, and its default in words where the code holds no value for it (a required key, a
//! default worked out when the file loads). Its type, range and default otherwise come from the
//! getter that checks it. The catalog refuses a key the loaders ask for that has no line here,
//! and a line for a key no loader asks for; the lines' order is docs/config.md's.

use super::catalog::FileKind;

/// One key's line.
pub(crate) struct Doc {
    pub kind: FileKind,
    /// The dotted path, `[]` for each array of tables (`block[].size`).
    pub path: &'static str,
    /// The default in words, only where the code holds none; empty where the getter holds it.
    pub default: &'static str,
    pub what: &'static str,
}

const fn session(path: &'static str, default: &'static str, what: &'static str) -> Doc {
    Doc {
        kind: FileKind::Session,
        path,
        default,
        what,
    }
}

const fn devices(path: &'static str, default: &'static str, what: &'static str) -> Doc {
    Doc {
        kind: FileKind::Devices,
        path,
        default,
        what,
    }
}

const fn scene(path: &'static str, default: &'static str, what: &'static str) -> Doc {
    Doc {
        kind: FileKind::Scene,
        path,
        default,
        what,
    }
}

const fn hand(path: &'static str, default: &'static str, what: &'static str) -> Doc {
    Doc {
        kind: FileKind::HandModel,
        path,
        default,
        what,
    }
}

/// Written with the default from the code, or words where it holds none ("" for a table).
pub(crate) const DOCS: &[Doc] = &[
    // Session files.
    session(
        "scene",
        "required",
        "The scene file, relative to this file.",
    ),
    session(
        "hand_model",
        "none: the built-in adult hand (config/hand.toml's numbers)",
        "The hand model file (bone lengths, finger radii, palm), relative to this file.",
    ),
    session("source", "", "What feeds the pipeline."),
    session(
        "source.kind",
        "",
        "The source: the scene's `[hand]` (scripted), a glove and tracker (devices), a \
         recording or CARL trace (replay), another machine's session (remote), a headset's \
         browser (webxr), a program of yours (external), a flat hand held still for tests \
         (null), or the participants of a shared world this session hosts (shared, with \
         `[shared]`); the keys below name the kind that takes them.",
    ),
    session(
        "source.rate_hz",
        "",
        "scripted, null: samples per second of the scripted (or still) glove and tracker.",
    ),
    session(
        "source.glove",
        "",
        "devices: the CyberGlove's table (its keys are listed under Device tables).",
    ),
    session(
        "source.tracker",
        "",
        "devices: the FASTRAK's table (its keys are listed under Device tables).",
    ),
    session(
        "source.file",
        "required",
        "replay: the recording (MCAP) or CARL trace to play, relative to this file.",
    ),
    session(
        "source.speed",
        "",
        "replay: the playing speed; 0: as fast as the slowest reader takes it, every sample \
         to every reader (the bus is lossless then, and `frame_hz` is not judged).",
    ),
    session(
        "source.offset",
        "",
        "replay, webxr: moves the recorded or tracked hand, metres (a standing user's hands \
         are about 1 m above the floor).",
    ),
    session(
        "source.loop",
        "",
        "replay: play the trace again when it ends, its source times going on, until stopped; \
         false: the session ends with the trace.",
    ),
    session(
        "source.topics",
        "",
        "replay: the trace's source topics to play, of \"glove\", \"tracker\" and \"joints\" \
         (as `ros2 bag play --topics`); empty: all it holds.",
    ),
    session(
        "source.hands",
        "",
        "replay: which hands of a CARL trace to play; one of our recordings plays the hands \
         it holds. Two hands are the paper model's.",
    ),
    session(
        "source.endpoint",
        "required",
        "remote: the other side's zenoh endpoint, `tls/HOST:PORT` (`tcp/` only with \
         `allow_plain`).",
    ),
    session(
        "source.allow_plain",
        "",
        "remote: allow a plain `tcp/` endpoint: in clear, and any peer that reaches the port \
         may read or inject.",
    ),
    session(
        "source.key_dir",
        "`$XDG_DATA_HOME/handblocks/link` (or `~/.local/share/handblocks/link`)",
        "remote: this side's link certificate and key, made on first use.",
    ),
    session(
        "source.peer_certificate",
        "this side's own certificate",
        "remote: the only peer certificate trusted.",
    ),
    session(
        "source.names",
        "",
        "remote: names a connecting side may use for this side, put in its certificate \
         besides localhost, its addresses and the endpoint's host.",
    ),
    session(
        "source.role",
        "",
        "remote: whether this side listens on `endpoint` or connects to it (retrying, so the \
         halves start in either order).",
    ),
    session(
        "source.key",
        "",
        "remote: the zenoh key prefix (a topic travels on KEY/TOPIC); both halves must use \
         the same.",
    ),
    session(
        "source.publish",
        "",
        "remote: topics sent back to the other side; only \"frame\" (the renderer's frame \
         stats).",
    ),
    session(
        "source.subscribe",
        "",
        "remote: topics taken in from the other side; must hold \"hand\" and \"world\" (the \
         renderer and recorder read them).",
    ),
    session(
        "source.tls",
        "",
        "webxr: serve HTTPS and WSS (WebXR needs a secure context); false: plain HTTP (for \
         `adb reverse` and tests).",
    ),
    session(
        "source.listen",
        "`\"0.0.0.0:8443\"` with tls, `\"127.0.0.1:8443\"` without",
        "webxr: the address the page and its socket are served on: an address and port, or \
         an address alone (port 8443).",
    ),
    session(
        "source.token",
        "a new random one each session",
        "webxr: the page's token, 16 to 128 characters of A-Z, a-z, 0-9, - and _.",
    ),
    session(
        "source.certificate_dir",
        "`$XDG_DATA_HOME/handblocks/webxr` (or `~/.local/share/handblocks/webxr`)",
        "webxr: where the certificate made on first use is kept for the next.",
    ),
    session(
        "source.hand",
        "",
        "webxr: the hands that drive the model; \"both\": each frame's right then left hand \
         (the paper model only).",
    ),
    session(
        "source.command",
        "",
        "external: the program that publishes the joints (Python's `handblocks.Source`) and \
         its arguments, run with `HANDBLOCKS_BUS` set; the session ends when it does.",
    ),
    session(
        "remote",
        "",
        "This session's topics sent to (or taken from) another machine over zenoh; not with \
         `[source] kind = \"remote\"`.",
    ),
    session(
        "remote.endpoint",
        "required",
        "The zenoh endpoint, `tls/HOST:PORT` (TLS 1.3 on QUIC, both sides authenticated; \
         `tcp/` only with `allow_plain`).",
    ),
    session(
        "remote.allow_plain",
        "",
        "Allow a plain `tcp/` endpoint: in clear, and any peer that reaches the port may read \
         or inject.",
    ),
    session(
        "remote.key_dir",
        "`$XDG_DATA_HOME/handblocks/link` (or `~/.local/share/handblocks/link`)",
        "This side's link certificate and key, made on first use.",
    ),
    session(
        "remote.peer_certificate",
        "this side's own certificate",
        "The only peer certificate trusted: the other side's.",
    ),
    session(
        "remote.names",
        "",
        "Names a connecting side may use for this side, put in its certificate besides \
         localhost, its addresses and the endpoint's host.",
    ),
    session(
        "remote.role",
        "",
        "Whether this side listens on `endpoint` (viewers connect here) or connects to it.",
    ),
    session(
        "remote.key",
        "",
        "The zenoh key prefix (a topic travels on KEY/TOPIC); both halves must use the same.",
    ),
    session("remote.publish", "", "Topics sent out."),
    session(
        "remote.subscribe",
        "",
        "Topics taken in from the other side: only \"frame\" (a remote renderer's frame \
         stats), none that `publish` sends.",
    ),
    session(
        "remote.wait_for_viewer_s",
        "",
        "Start the source only once a viewer takes every topic sent, waiting up to this many \
         seconds; 0: do not wait.",
    ),
    session(
        "shared",
        "",
        "This session's side of a shared world (docs/sessions.md \"Shared sessions\"): the \
         host's (`[source] kind = \"shared\"`) or a participant's (any other source).",
    ),
    session(
        "shared.listen",
        "`tls/0.0.0.0:7460` (every interface)",
        "host: where participants connect, `tls/HOST:PORT` (`tcp/` only with `allow_plain`).",
    ),
    session(
        "shared.host",
        "required to join",
        "participant: the host's address, `tls/HOST:PORT` (`handblocks launch shared-host` \
         prints it).",
    ),
    session(
        "shared.allow_plain",
        "",
        "Allow a plain `tcp/` endpoint: in clear; only the token keeps others out.",
    ),
    session(
        "shared.key_dir",
        "`$XDG_DATA_HOME/handblocks/link` (or `~/.local/share/handblocks/link`)",
        "This side's link certificate and key, made on first use.",
    ),
    session(
        "shared.peer_certificate",
        "this side's own certificate",
        "The only peer certificate trusted: the other side's.",
    ),
    session(
        "shared.names",
        "",
        "host: names participants may use for it, put in its certificate besides localhost, \
         its addresses and the endpoint's host.",
    ),
    session(
        "shared.key",
        "",
        "The zenoh key prefix; the host and its participants must use the same.",
    ),
    session(
        "shared.token",
        "host: a new random one each session, printed; participant: required to join",
        "What a participant gives to join (at least 16 characters of A-Za-z0-9-_).",
    ),
    session(
        "shared.name",
        "",
        "participant: how the host's report names it (1 to 32 characters of A-Za-z0-9-_.).",
    ),
    session(
        "shared.drop_after_s",
        "",
        "host: a participant none of whose hands came for this long is named and dropped; its \
         hands let go.",
    ),
    session(
        "shared.hold_ms",
        "",
        "host: a participant none of whose hands came for this long has them sent as lost \
         (tracked = 0), holding what they hold.",
    ),
    session("viewer", "", "A live Foxglove view of the session."),
    session(
        "viewer.foxglove",
        "none: no view",
        "`HOST:PORT` to serve the live topics on over the Foxglove WebSocket protocol (port 0: \
         any free port, printed at start).",
    ),
    session(
        "viewer.foxglove_clients",
        "",
        "Foxglove clients served at once; the next is answered 503.",
    ),
    session("renderer", "", "The stereo renderer."),
    session(
        "renderer.mode",
        "",
        "\"window\" (needs a display), \"headless\" (frames and the preview) or \"off\" (no \
         renderer).",
    ),
    session("renderer.width", "", "Each eye's image width, pixels."),
    session("renderer.height", "", "Each eye's image height, pixels."),
    session(
        "renderer.output",
        "",
        "How the two eyes' images are put together: side by side, red-cyan anaglyph, or one \
         image per eye.",
    ),
    session(
        "renderer.ipd_mm",
        "",
        "The distance between the eyes, millimetres (adults: 50-75).",
    ),
    session(
        "renderer.screen_distance_m",
        "",
        "The screen plane both eyes' frusta share (zero disparity), metres from the eyes.",
    ),
    session("renderer.screen_width_m", "", "The screen's width, metres."),
    session(
        "renderer.eye",
        "",
        "Where the eyes' midpoint is, world frame, metres. With neither `eye` nor `target` \
         given the renderer frames the scene itself (its blocks, the hand's reach), looking \
         from the default eye towards the default target.",
    ),
    session(
        "renderer.target",
        "",
        "What the eyes look at, world frame, metres; must differ from `eye`.",
    ),
    session(
        "renderer.shadows",
        "",
        "Draw the blocks' and the hand's shadows.",
    ),
    session(
        "renderer.frames_every",
        "",
        "With `launch --frames-dir`, write every Nth frame.",
    ),
    session(
        "renderer.own_cpus",
        "",
        "Run the renderer and recorder on CPUs apart from the pipeline's (source, kinematics, \
         stepper) when the machine has two or more.",
    ),
    session("recorder", "", "Recording every topic to an MCAP file."),
    session(
        "recorder.file",
        "none: no recording (or `launch --record FILE`)",
        "The recording, relative to this file.",
    ),
    session(
        "recorder.flush_ms",
        "",
        "A chunk goes to the operating system once this old (or `chunk_kib` big), \
         milliseconds: the most a crash of the recorder loses.",
    ),
    session(
        "recorder.chunk_kib",
        "",
        "... or once it holds this many KiB uncompressed.",
    ),
    session(
        "recorder.scene_hz",
        "",
        "How often, at most, the `/scene` and `/tf` channels (Foxglove's 3D panel: the scene, the hand's frame tree) are written; 0: never.",
    ),
    session(
        "budget",
        "",
        "The interactive-rate budget: exceeding a limit fails the session (exit status 1).",
    ),
    session(
        "budget.frame_hz",
        "",
        "The renderer's frame rate the session asks for.",
    ),
    session(
        "budget.origin_to_world_p99_us",
        "none: not judged",
        "The most the 99th percentile of origin -> world (a source sample to the world made \
         of it) may be, microseconds.",
    ),
    session(
        "budget.hop_p99_us",
        "none: not judged",
        "The most the 99th percentile of any stage's hop (publish to receive) may be, \
         microseconds.",
    ),
    session(
        "budget.origin_to_photon_p99_ms",
        "none: not judged",
        "The most the 99th percentile of origin -> photon may be, milliseconds; refused with \
         `[renderer] mode = \"off\"`.",
    ),
    session(
        "budget.max_dropped",
        "none: not judged",
        "The most samples any topic may drop.",
    ),
    session(
        "budget.source_silence_ms",
        "",
        "The longest the source may go without a sample (from the start, between samples, to \
         the end), milliseconds; judged in every session.",
    ),
    session(
        "budget.frame_rate_margin",
        "",
        "How far below `frame_hz` (or the world's rate, when lower) the frame rate may fall, \
         as a fraction; judged in every rendering session.",
    ),
    session(
        "pipeline",
        "",
        "How the pipeline's stages wait for their next sample.",
    ),
    session(
        "pipeline.wait",
        "",
        "\"event\": sleep until woken; \"spin\": poll always (a core each); \"adaptive\": sleep \
         until shortly before the next sample is due, then poll a bounded window.",
    ),
    session(
        "pipeline.wake",
        "",
        "What wakes a sleeping stage: \"doorbell\": kinematics and the stepper each sleep on a \
         futex word every publisher of what they read rings (the cheapest wake-up measured); \
         \"event\": every stage on iceoryx2's event (a Unix datagram per inlet), as before.",
    ),
    session(
        "supervise",
        "",
        "What the launcher does when a process dies mid-session (a crash, SIGKILL).",
    ),
    session(
        "supervise.restart",
        "",
        "\"never\": the session fails at once; \"on-failure\": the process is started again, \
         the others go on.",
    ),
    session(
        "supervise.max_restarts",
        "",
        "Restarts allowed per process over the session; one more fails it.",
    ),
    session(
        "supervise.backoff_ms",
        "",
        "The wait before a process's first restart, milliseconds; doubled for each further \
         restart of it.",
    ),
    session(
        "supervise.backoff_max_ms",
        "",
        "The longest wait before a restart, milliseconds; at least `backoff_ms`.",
    ),
    // Device tables.
    devices(
        "source.glove.port",
        "required",
        "The glove's serial device, e.g. /dev/ttyUSB0 (or an emulator's link).",
    ),
    devices("source.glove.baud", "", "The serial line's rate."),
    devices(
        "source.glove.sensors",
        "none: what the glove reports",
        "The glove size the session insists on.",
    ),
    devices(
        "source.glove.calibration",
        "none: a nominal mapping",
        "The calibration file, relative to the session file (format: \
         config/devices/README.md).",
    ),
    devices(
        "source.glove.mode",
        "",
        "\"streamed\": the glove sends records on its own (the lowest latency); \"polled\": \
         the driver asks at `rate_hz`.",
    ),
    devices("source.glove.rate_hz", "", "The poll rate."),
    devices(
        "source.glove.answer_ms",
        "",
        "How long the glove may take to answer a command at open.",
    ),
    devices(
        "source.glove.silence_ms",
        "",
        "No valid record for this long: the glove stopped answering; reported, and the link \
         reconnected.",
    ),
    devices(
        "source.tracker.port",
        "required",
        "The tracker's serial device, e.g. /dev/ttyUSB1 (or an emulator's link).",
    ),
    devices(
        "source.tracker.baud",
        "",
        "The serial line's rate (the FASTRAK's switches set it).",
    ),
    devices("source.tracker.format", "", "The record encoding."),
    devices(
        "source.tracker.units",
        "",
        "The position units the tracker reports in (centimetres or inches).",
    ),
    devices(
        "source.tracker.orientation",
        "",
        "The orientation item asked for: quaternions (no gimbal lock) or Euler angles.",
    ),
    devices(
        "source.tracker.mode",
        "",
        "\"continuous\": the tracker sends at its own rate; \"polled\": the driver asks at \
         `rate_hz`.",
    ),
    devices("source.tracker.rate_hz", "", "The poll rate."),
    devices("source.tracker.station", "", "The receiver on the hand."),
    devices(
        "source.tracker.to_world",
        "the identity",
        "The transmitter's pose in the world, in project axes (y up).",
    ),
    devices(
        "source.tracker.to_world.position",
        "",
        "The transmitter's position, metres.",
    ),
    devices(
        "source.tracker.to_world.rotation",
        "",
        "The transmitter's rotation, quaternion x, y, z, w.",
    ),
    devices(
        "source.tracker.wrist_offset",
        "the identity",
        "The wrist's pose in the receiver's frame (project axes).",
    ),
    devices(
        "source.tracker.wrist_offset.position",
        "",
        "The wrist's position from the receiver, metres.",
    ),
    devices(
        "source.tracker.wrist_offset.rotation",
        "",
        "The wrist's rotation from the receiver, quaternion x, y, z, w.",
    ),
    devices(
        "source.tracker.answer_ms",
        "",
        "How long the tracker may take to answer a command at open.",
    ),
    devices(
        "source.tracker.silence_ms",
        "",
        "No valid record for this long: the tracker stopped answering; reported, and the \
         link reconnected.",
    ),
    // Scene files.
    scene("world", "", "The world's settings."),
    scene(
        "world.step_hz",
        "",
        "Fixed steps per second (dt = 1 / step_hz).",
    ),
    scene("world.gravity", "", "g, m/s^2 (R7)."),
    scene(
        "world.model",
        "",
        "\"paper\": the rules R1-R14; \"precise\": the rigid-body reference (rapier3d, its \
         settings `[precise]`).",
    ),
    scene(
        "world.contact_eps",
        "",
        "The contact tolerance, metres (model.md \"Conventions\"; R1, R3, R8).",
    ),
    scene(
        "world.hull_eps",
        "",
        "The hull and support tolerance, metres (R4, R9, R10, R14).",
    ),
    scene("world.angle_eps", "", "The angle tolerance, radians."),
    scene(
        "world.grasp_angle",
        "",
        "R3: the angle, degrees, that two or more contacts' normals must open wider than to \
         grasp.",
    ),
    scene(
        "world.release_angle",
        "grasp_angle's value",
        "R3 (extension): below this angle, degrees, a grasp ends; at most `grasp_angle`.",
    ),
    scene(
        "world.throw_window",
        "",
        "R13 (extension): steps averaged for a throw's velocity; 1 in the paper.",
    ),
    scene(
        "world.hands",
        "",
        "\"paper\": R3 and R13; \"tracked\": the tracked-hand rules T1-T3 beside them (for \
         tracked hands).",
    ),
    scene(
        "tracked",
        "",
        "The tracked-hand rules' numbers, read whatever `world.hands` says.",
    ),
    scene(
        "tracked.grip_margin",
        "",
        "T1: a grasp ends when the grip opens by this much, metres.",
    ),
    scene(
        "tracked.grip_open_time",
        "",
        "T1: ... and has stayed open this long, seconds.",
    ),
    scene(
        "tracked.gap_hold",
        "",
        "T2: a hand that is not tracked keeps what it holds this long, seconds.",
    ),
    scene(
        "tracked.throw_fit_window",
        "",
        "T3: the throw's line is fitted over this long before the release, seconds.",
    ),
    scene(
        "precise",
        "",
        "The precise model's (rapier3d's) settings, read whatever `world.model` says.",
    ),
    scene(
        "precise.substeps",
        "",
        "Solver substeps per step (the substep is dt / substeps).",
    ),
    scene(
        "precise.solver_iterations",
        "",
        "Solver (PGS) iterations per substep.",
    ),
    scene(
        "precise.contact_hz",
        "none: 0.125 / substep dt, the stiffest a substep resolves",
        "Contact stiffness, the natural frequency of the contact spring, Hz.",
    ),
    scene(
        "precise.contact_damping",
        "",
        "The contact spring's damping ratio.",
    ),
    scene(
        "precise.friction",
        "",
        "Coulomb friction coefficient, blocks and floor.",
    ),
    scene(
        "precise.restitution",
        "",
        "Restitution, blocks and floor (0: no bounce, as R8).",
    ),
    scene(
        "precise.ccd",
        "",
        "Continuous collision detection (no tunnelling).",
    ),
    scene("precise.sleep", "", "Whether still bodies may sleep."),
    scene(
        "precise.allowed_penetration",
        "",
        "The penetration left uncorrected, metres.",
    ),
    scene(
        "precise.bare_finger_radius",
        "",
        "The radius of a bare check-point hand's fingers, metres.",
    ),
    scene(
        "effects",
        "",
        "What the stepper simulates; an effect that is off costs nothing.",
    ),
    scene("effects.gravity", "", "R7: gravity."),
    scene("effects.inertia", "", "R7, R13: inertia."),
    scene(
        "effects.floor",
        "",
        "\"tipping\": R8 and R9; \"rest\": R8 only; \"none\": no floor.",
    ),
    scene(
        "effects.hand",
        "",
        "\"grasp\": R4-R6; \"push\": R4 and R6 only; \"none\": the hand acts on nothing.",
    ),
    scene(
        "effects.carry",
        "",
        "R10: a block the hand moves moves the blocks it interferes with.",
    ),
    scene(
        "effects.stacking",
        "",
        "\"paper\": R11 (a block touching another stays where it is); \"supported\": R14 \
         (statics).",
    ),
    scene(
        "block",
        "",
        "The blocks, one table each (at most 4096 blocks in a scene).",
    ),
    scene(
        "block[].name",
        "\"block\" and its index: block0, block1, ...",
        "The block's name in reports and events, unique, 1 to 128 characters; a colour word \
         first (red_...) gives its colour.",
    ),
    scene(
        "block[].shape",
        "",
        "The shape: a box, a wedge (half the size box), a tetrahedron (its corner), or the \
         convex hull of `vertices`.",
    ),
    scene(
        "block[].size",
        "",
        "Full extents x, y, z, metres (box, wedge, tetra).",
    ),
    scene(
        "block[].position",
        "required",
        "Where the centre of gravity starts, metres.",
    ),
    scene(
        "block[].rotation",
        "",
        "The starting rotation, a unit quaternion x, y, z, w (to within 0.001).",
    ),
    scene("block[].velocity", "", "The initial inertia, m/s."),
    scene(
        "block[].color",
        "none: the name's colour word, else the palette's",
        "The block's colour, sRGB red, green, blue.",
    ),
    scene(
        "block[].count",
        "",
        "Copies along x, y and z (whole numbers): a lattice of blocks named NAME_X_Y_Z, the \
         first at `position`.",
    ),
    scene(
        "block[].spacing",
        "required with count; none for one block",
        "The distance between neighbouring copies' centres, metres.",
    ),
    scene(
        "block[].vertices",
        "required for shape = \"hull\"",
        "The hull's vertices in the block's own frame, metres; `position` places their \
         centre of gravity.",
    ),
    scene(
        "hand",
        "",
        "The scripted hand (the right, with a `[left_hand]`): keyframes, linearly \
         interpolated; after the last the hand holds still.",
    ),
    scene("hand.key", "", "The keyframes, at least one."),
    scene(
        "hand.key[].t",
        "",
        "The key's time, seconds; strictly increasing.",
    ),
    scene(
        "hand.key[].wrist",
        "required",
        "The wrist's position, metres.",
    ),
    scene(
        "hand.key[].wrist_rotation",
        "",
        "The wrist's rotation, a unit quaternion x, y, z, w.",
    ),
    scene(
        "hand.key[].grip",
        "",
        "0 open .. 1 fist, through the hand model (when neither `angles` nor `fingers`).",
    ),
    scene(
        "hand.key[].angles",
        "none: grip",
        "Glove angles, radians, 18 or 22 in CyberGlove sensor order, through the hand model.",
    ),
    scene(
        "hand.key[].fingers",
        "none: grip",
        "Bare check points per finger, knuckle to tip, in the wrist's frame: no hand model, \
         no palm; every key the same counts.",
    ),
    scene(
        "left_hand",
        "",
        "A second scripted hand, the left (model.md \"Two hands\"; the paper model only): \
         keys as `[hand]`'s, shaped the same way.",
    ),
    scene("left_hand.key", "", "As `hand.key`."),
    scene("left_hand.key[].t", "", "As `hand.key[].t`."),
    scene(
        "left_hand.key[].wrist",
        "required",
        "As `hand.key[].wrist`.",
    ),
    scene(
        "left_hand.key[].wrist_rotation",
        "",
        "As `hand.key[].wrist_rotation`.",
    ),
    scene(
        "left_hand.key[].grip",
        "",
        "As `hand.key[].grip`; the hand model's left is its right mirrored in the wrist's x.",
    ),
    scene(
        "left_hand.key[].angles",
        "none: grip",
        "As `hand.key[].angles`.",
    ),
    scene(
        "left_hand.key[].fingers",
        "none: grip",
        "As `hand.key[].fingers`, taken as given.",
    ),
    // Hand model files.
    hand("palm", "", "The palm."),
    hand(
        "palm.half_width",
        "",
        "Half the palm's width across the knuckles, metres.",
    ),
    hand(
        "palm.half_thickness",
        "",
        "Half the palm's thickness (y), metres.",
    ),
    hand("thumb", "", "The thumb."),
    hand("thumb.base", "", "The thumb's base (CMC joint), metres."),
    hand(
        "thumb.bones",
        "",
        "Metacarpal, proximal and distal bone lengths, metres.",
    ),
    hand("thumb.radius", "", "The thumb's radius, metres."),
    hand("index", "", "The index finger."),
    hand("index.knuckle", "", "The knuckle (MCP joint), metres."),
    hand(
        "index.bones",
        "",
        "Proximal, middle and distal phalanx lengths, metres.",
    ),
    hand("index.radius", "", "The finger's radius, metres."),
    hand("middle", "", "The middle finger, as `index`."),
    hand("middle.knuckle", "", "As `index.knuckle`."),
    hand("middle.bones", "", "As `index.bones`."),
    hand("middle.radius", "", "As `index.radius`."),
    hand("ring", "", "The ring finger, as `index`."),
    hand("ring.knuckle", "", "As `index.knuckle`."),
    hand("ring.bones", "", "As `index.bones`."),
    hand("ring.radius", "", "As `index.radius`."),
    hand("little", "", "The little finger, as `index`."),
    hand("little.knuckle", "", "As `index.knuckle`."),
    hand("little.bones", "", "As `index.bones`."),
    hand("little.radius", "", "As `index.radius`."),
];
