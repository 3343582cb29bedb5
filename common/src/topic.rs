//! Topic names and the stages (processes) that publish and read them.

/// Every publish-subscribe service of a session. Each is paired with an event service of the
/// same name, so consumers sleep until a sample arrives instead of spinning.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Topic {
    Glove = 0,
    Tracker = 1,
    Joints = 2,
    Hand = 3,
    World = 4,
    Frame = 5,
    Latency = 6,
}

impl Topic {
    pub const ALL: [Topic; 7] = [
        Topic::Glove,
        Topic::Tracker,
        Topic::Joints,
        Topic::Hand,
        Topic::World,
        Topic::Frame,
        Topic::Latency,
    ];

    /// The service name; the session's own iceoryx2 prefix keeps sessions apart.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Glove => "glove",
            Topic::Tracker => "tracker",
            Topic::Joints => "joints",
            Topic::Hand => "hand",
            Topic::World => "world",
            Topic::Frame => "frame",
            Topic::Latency => "latency",
        }
    }

    pub fn from_u32(v: u32) -> Option<Topic> {
        Topic::ALL.get(v as usize).copied()
    }

    /// Samples a subscriber may hold unread before the oldest is overwritten. Sized for a
    /// second of a 1 kHz source so a stage that is descheduled for a while loses nothing; the
    /// renderer drains everything and keeps only the newest world state.
    pub fn subscriber_buffer(self) -> usize {
        match self {
            Topic::Glove | Topic::Tracker | Topic::Joints | Topic::Hand | Topic::World => 1024,
            Topic::Frame => 256,
            Topic::Latency => 32,
        }
    }
}

/// The processes of a session.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    Acquisition = 0,
    Replay = 1,
    Kinematics = 2,
    Stepper = 3,
    Renderer = 4,
    Recorder = 5,
}

impl Stage {
    pub const ALL: [Stage; 6] = [
        Stage::Acquisition,
        Stage::Replay,
        Stage::Kinematics,
        Stage::Stepper,
        Stage::Renderer,
        Stage::Recorder,
    ];

    /// The name used on the command line (`handblocks service NAME`) and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Acquisition => "acquisition",
            Stage::Replay => "replay",
            Stage::Kinematics => "kinematics",
            Stage::Stepper => "stepper",
            Stage::Renderer => "renderer",
            Stage::Recorder => "recorder",
        }
    }

    pub fn from_name(name: &str) -> Option<Stage> {
        Stage::ALL.iter().copied().find(|s| s.name() == name)
    }

    pub fn from_u32(v: u32) -> Option<Stage> {
        Stage::ALL.get(v as usize).copied()
    }
}
