//! The stages: the processes of a session, one row each, with what each is in the graph. The
//! topic table ([`crate::topic`]) says which of them publishes and reads each topic; together
//! they are the process graph, declared once.

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

/// Declares the [`Stage`] enum and its per-stage facts from one row per stage, in pipeline
/// order: with the topic table above (which stage publishes and reads each topic) it is the
/// process graph, declared once.
macro_rules! stage_table {
    (
        $(#[$enum_doc:meta])*
        pub enum Stage {
            $(
                $(#[$doc:meta])*
                $stage:ident = $n:literal { name: $name:literal, role: $role:ident $(,)? }
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
        }
    };
}

stage_table! {
    /// The processes of a session, one row each, upstream first. Which of them a session runs
    /// is the session's ([`crate::config::Session::graph`]); which topics each may open a port
    /// on is the topic table's (a stage's [`crate::bus::Bus::for_stage`] refuses any other).
    ///
    /// To add a process: (1) its row here; (2) its rows' `publishers`/`readers` in the topic
    /// table; (3) when a session runs it, in `Session::graph`; (4) its crate's `service::run`
    /// in `handblocks service` (services/handblocks/service.rs).
    pub enum Stage {
        /// The glove and tracker, or the scene's scripted hand.
        Acquisition = 0 { name: "acquisition", role: Source },
        /// A recorded hand (one of our recordings, or a CARL trace).
        Replay = 1 { name: "replay", role: Source },
        /// Glove + tracker (or joints) to the hand model.
        Kinematics = 2 { name: "kinematics", role: Reader },
        /// The block world.
        Stepper = 3 { name: "stepper", role: Reader },
        /// The stereo view.
        Renderer = 4 { name: "renderer", role: Reader },
        /// The MCAP recording.
        Recorder = 5 { name: "recorder", role: Reader },
        /// Forwards chosen topics between this session's bus and other machines (zenoh) or a
        /// live Foxglove view: a reader of what it sends out, the publisher of what it takes
        /// in. It is a reader of every topic and a publisher of every sample topic in the
        /// table, but it opens ports only on the topics its session names
        /// ([`crate::config::session::Bridge`]).
        Bridge = 6 { name: "bridge", role: Bridge },
        /// A headset's browser (WebXR hand input): serves the page, publishes the hand it
        /// sends as joints, and sends it the world to draw.
        Webxr = 7 { name: "webxr", role: Source },
        /// A program of the user's (Python's `handblocks.Source`): started by the launcher
        /// as the session's source, it publishes OpenXR hand joints it made itself (a
        /// webcam hand tracker, a model), stamped, checked and counted as any source's.
        External = 8 { name: "external", role: Source },
    }
}

impl Stage {
    pub fn from_name(name: &str) -> Option<Stage> {
        Stage::ALL.iter().copied().find(|s| s.name() == name)
    }

    pub fn from_u32(v: u32) -> Option<Stage> {
        Stage::ALL.get(v as usize).copied()
    }
}
