//! The stages: the processes of a session, one row each, with what each is in the graph. The
//! topic table ([`crate::topic`]) says which of them publishes and reads each topic; together
//! they are the process graph, declared once.

use crate::samples::DeviceKind;

/// What a stage is in the process graph: where a session's samples start, or a reader of them
/// (which may publish what it makes of them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Publishes a hand's samples (devices, a script, a trace): the launcher starts it last,
    /// once every reader of its topics is attached, and stops it first.
    Source,
    /// Reads what the stages before it publish; started before the source, upstream first,
    /// and stopped after it, downstream last, so that each drains what its upstream sent.
    Reader,
    /// The bridge: a reader of what it sends to other machines, a publisher of what it takes
    /// in, and the source of a remote-fed session (a viewer).
    Bridge,
}

/// Which CPUs a stage's process runs on when the launcher pins a session
/// (`[renderer] own_cpus`): the pipeline's share, or the consumers' beside the renderer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cores {
    /// On the path from a hand to the world: the cores the stepper needs.
    Pipeline,
    /// Off that path (what it does never delays the world), or of unknown weight (a user's
    /// program): beside the renderer.
    Consumers,
}

/// How the launcher sets a stage's process's scheduling, so that a consumer never delays the
/// world.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Priority {
    /// As the launcher's own.
    Normal,
    /// A higher nice value: light and latency-free (the recorder).
    Lowered,
    /// `SCHED_IDLE` (and the higher nice value): any pipeline stage that wakes takes the core
    /// at once, and this one still gets every cycle the pipeline leaves (the renderer, whose
    /// software rasteriser would otherwise take the stepper's cores).
    Idle,
}

/// What a restarted stage's process does with the file or folder it writes, so that the dead
/// process's output stays whole (`[supervise] restart = "on-failure"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OnRestart {
    /// It writes nothing of its own that a restart could overwrite.
    Resume,
    /// It writes the next segment of its file (`session.1.mcap`, ...), and the launcher counts
    /// what the recording lost between the segments.
    NextSegment,
    /// It writes into a folder of its own beside the dead one's (`restart-N/`).
    OwnFolder,
}

/// Declares the [`Stage`] enum and its per-stage facts from one row per stage, in pipeline
/// order: with the topic table (which stage publishes and reads each topic) it is the process
/// graph, declared once. Every fact of a stage that the launcher, the reports and `handblocks
/// service` need is a column here, so no other crate matches on a stage to learn it.
macro_rules! stage_table {
    (
        $(#[$enum_doc:meta])*
        pub enum Stage {
            $(
                $(#[$doc:meta])*
                $stage:ident = $n:literal {
                    name: $name:literal,
                    role: $role:ident,
                    selected_by: [$($kind:literal),* $(,)?],
                    cores: $cores:ident,
                    priority: $priority:ident,
                    on_restart: $on_restart:ident,
                    exit_wait_s: $exit_wait_s:literal,
                    devices: [$($device:ident),* $(,)?],
                    photon_label: $photon_label:literal,
                    wakes_by: $wakes_by:ident $(,)?
                }
            ),* $(,)?
        }
    ) => {
        $(#[$enum_doc])*
        #[repr(u32)]
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Stage {
            $($(#[$doc])* $stage = $n,)*
        }

        impl Stage {
            /// Every stage, in table order (`Stage as usize` indexes it).
            pub const ALL: [Stage; [$(Stage::$stage),*].len()] = [$(Stage::$stage),*];

            /// The name used on the command line (`handblocks service NAME`), as the process's
            /// bus node, and in reports.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Stage::$stage => $name,)*
                }
            }

            /// What the stage is in the graph.
            pub const fn role(self) -> Role {
                match self {
                    $(Stage::$stage => Role::$role,)*
                }
            }

            /// The `[source] kind` values that make this stage a session's source (none for a
            /// stage that is never one).
            pub const fn selected_by(self) -> &'static [&'static str] {
                match self {
                    $(Stage::$stage => &[$($kind),*],)*
                }
            }

            /// Where the launcher pins it.
            pub const fn cores(self) -> Cores {
                match self {
                    $(Stage::$stage => Cores::$cores,)*
                }
            }

            /// How the launcher schedules it.
            pub const fn priority(self) -> Priority {
                match self {
                    $(Stage::$stage => Priority::$priority,)*
                }
            }

            /// What a restart of it writes.
            pub const fn on_restart(self) -> OnRestart {
                match self {
                    $(Stage::$stage => OnRestart::$on_restart,)*
                }
            }

            /// How long the launcher waits for it to exit once released: what it still does
            /// after its final report (the renderer draws and encodes its preview).
            pub const fn exit_wait(self) -> std::time::Duration {
                match self {
                    $(Stage::$stage => std::time::Duration::from_secs($exit_wait_s),)*
                }
            }

            /// The devices whose counters its final report may carry.
            pub const fn devices(self) -> &'static [DeviceKind] {
                match self {
                    $(Stage::$stage => &[$(DeviceKind::$device),*],)*
                }
            }

            /// What its [`crate::latency::Metric::Photon`] measures, as the report's table
            /// names it (printed only for a stage that records that metric).
            pub const fn photon_label(self) -> &'static str {
                match self {
                    $(Stage::$stage => $photon_label,)*
                }
            }

            /// What wakes it for a sample on its inlets ([`WakesBy`]).
            pub const fn wakes_by(self) -> WakesBy {
                match self {
                    $(Stage::$stage => WakesBy::$wakes_by,)*
                }
            }
        }
    };
}

stage_table! {
    /// The processes of a session, one row each, upstream first. Which of them a session runs
    /// is the session's ([`crate::config::Session::graph`]); which topics each may open a port
    /// on is the topic table's (a stage's [`crate::bus::Bus::for_stage`] refuses any other).
    ///
    /// To add a process: (1) its row here; (2) its rows' `publishers`/`readers` in the topic
    /// table; (3) its crate, whose `service::run(&Session, &Bus, &Launch)` is the process,
    /// named once in `handblocks service`'s list (services/handblocks/service.rs).
    pub enum Stage {
        /// The glove and tracker, or the scene's scripted hand.
        Acquisition = 0 {
            name: "acquisition", role: Source, selected_by: ["scripted", "devices"],
            cores: Pipeline, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [Glove, Tracker], photon_label: "origin->px",
            wakes_by: Event,
        },
        /// A recorded hand (one of our recordings, or a CARL trace).
        Replay = 1 {
            name: "replay", role: Source, selected_by: ["replay"],
            cores: Pipeline, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [], photon_label: "origin->px",
            wakes_by: Event,
        },
        /// Glove + tracker (or joints) to the hand model.
        Kinematics = 2 {
            name: "kinematics", role: Reader, selected_by: [],
            cores: Pipeline, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [], photon_label: "origin->px",
            wakes_by: Doorbell,
        },
        /// The block world.
        Stepper = 3 {
            name: "stepper", role: Reader, selected_by: [],
            cores: Pipeline, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [], photon_label: "origin->px",
            wakes_by: Doorbell,
        },
        /// The stereo view. After its final report it draws its preview again with the
        /// preview's own camera and encodes it (seconds on a loaded machine).
        Renderer = 4 {
            name: "renderer", role: Reader, selected_by: [],
            cores: Consumers, priority: Idle, on_restart: OwnFolder, exit_wait_s: 60,
            devices: [], photon_label: "origin->px",
            wakes_by: Event,
        },
        /// The MCAP recording.
        Recorder = 5 {
            name: "recorder", role: Reader, selected_by: [],
            cores: Consumers, priority: Lowered, on_restart: NextSegment, exit_wait_s: 5,
            devices: [], photon_label: "origin->px",
            wakes_by: Event,
        },
        /// Forwards chosen topics between this session's bus and other machines (zenoh) or a
        /// live Foxglove view: a reader of what it sends out, the publisher of what it takes
        /// in. It is a reader of every topic and a publisher of every sample topic in the
        /// table, but it opens ports only on the topics its session names
        /// ([`crate::config::session::Bridge`]). What it sends is off the pipeline's path.
        Bridge = 6 {
            name: "bridge", role: Bridge, selected_by: ["remote", "shared"],
            cores: Consumers, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [], photon_label: "origin->px",
            wakes_by: Event,
        },
        /// A headset's browser (WebXR hand input): serves the page, publishes the hand it
        /// sends as joints, and sends it the world to draw. Its photon metric is the page's
        /// round trip: a frame sent to the world that answers it drawn on the headset.
        Webxr = 7 {
            name: "webxr", role: Source, selected_by: ["webxr"],
            cores: Pipeline, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [Headset], photon_label: "sent->drawn",
            wakes_by: Event,
        },
        /// A program of the user's (Python's `handblocks.Source`): started by the launcher
        /// as the session's source, it publishes OpenXR hand joints it made itself (a
        /// webcam hand tracker, a model), stamped, checked and counted as any source's. Of
        /// unknown weight (a webcam tracker runs a neural network per frame), so beside the
        /// renderer, not on the cores the stepper needs.
        External = 8 {
            name: "external", role: Source, selected_by: ["external"],
            cores: Consumers, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [External], photon_label: "origin->px",
            wakes_by: Event,
        },
        /// A flat hand held still (`services/null`), for tests and for measuring a pipeline
        /// whose hand never moves.
        Null = 9 {
            name: "null", role: Source, selected_by: ["null"],
            cores: Pipeline, priority: Normal, on_restart: Resume, exit_wait_s: 5,
            devices: [], photon_label: "origin->px",
            wakes_by: Event,
        },
    }
}

/// What wakes a stage when a sample comes on one of its inlets (issue 46).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WakesBy {
    /// Its own doorbell ([`crate::bus::Doorbell`]): one futex word every publisher of a topic
    /// it reads rings; the cheapest wake-up measured, for a stage that sleeps on its inlets
    /// and a deadline only.
    Doorbell,
    /// iceoryx2's event, a descriptor per inlet slept on in `ppoll`, beside the stage's other
    /// descriptors (a device, a server's or a zenoh callback's wake), or because it reads
    /// topics chosen at run time (the recorder, the bridge).
    Event,
}

impl Stage {
    pub fn from_name(name: &str) -> Option<Stage> {
        Stage::ALL.iter().copied().find(|s| s.name() == name)
    }

    pub fn from_u32(v: u32) -> Option<Stage> {
        Stage::ALL.get(v as usize).copied()
    }
}
