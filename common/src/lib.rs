//! The contract between handblocks processes, and nothing else.
//!
//! Every process links this crate: the sample type of every topic (fixed `#[repr(C)]` layouts
//! that travel zero-copy through iceoryx2), the [`Stamp`] every sample starts with, topic names, the bus helpers that pair each
//! publish-subscribe service with an event service, latency histograms, and the session and
//! scene configuration files with errors that name the file, the key and the allowed values.
//! Libraries that only some processes need lie beside it (`common/recording`: the MCAP
//! recording format), so that a process links only what it uses.

pub mod bus;
pub mod config;
pub mod glove;
pub mod latency;
pub mod node;
pub mod output;
pub mod samples;
pub mod shutdown;
pub mod stage;
pub mod stamp;
pub mod topic;
pub mod world_hash;

pub use samples::*;
pub use stamp::{monotonic_ns, Stamp};
pub use topic::{topics, Stage, Topic, TopicSpec};
