//! The bridge process (issue 17): it carries a session's topics past the end of shared memory.
//!
//! * Across machines, over **zenoh** ([`link`]): chosen topics go out on one zenoh key each
//!   (`KEY/TOPIC`), as the very bytes a recording holds (no re-encoding), and the other side's
//!   bridge publishes them on its own bus, so its renderer and recorder cannot tell them from
//!   local samples. Stamps cross hosts by a clock offset the bridges estimate ([`clock`]).
//! * To a **live Foxglove view** ([`viewer`]), over the Foxglove WebSocket protocol, with the
//!   recording's schemas and a 3D scene of the blocks and the hand.
//!
//! * A link is protected ([`identity`]): TLS 1.3 with both sides' certificates, each trusting
//!   only the authority it was told to, and what it refuses is counted by name ([`refusals`]).
//!
//! The session file asks for it (`[remote]`, `[source] kind = "remote"`, `[viewer]`); the
//! launcher then starts `handblocks service bridge` as a reader of what it sends (or, in a
//! remote-fed session, as the source). Backpressure never reaches the pipeline: see [`link`].

pub mod clock;
pub mod gate;
pub mod identity;
pub mod link;
pub mod peer_wire;
pub mod refusals;
pub mod service;
pub mod shared;
pub mod viewer;

common::process!(
    /// The bridge stage's process (the link to other machines and the live Foxglove view), as
    /// `handblocks service bridge` runs it.
    Bridge,
    service::BridgeError,
    service::run
);
