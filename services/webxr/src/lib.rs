//! The webxr process: a headset's browser as a session's live hand and its stereo view.
//!
//! Anyone who builds hand interaction today owns a headset whose browser gives WebXR hand
//! input (25 joints per hand, every display frame) and draws a stereo view. This process
//! serves a page ([`page`]) and a WebSocket on one port; the page sends both hands' joints
//! each XR frame (`webxr_wire`'s hands frame), and this process publishes the driving hand on
//! `joints`, as a CARL replay does, so the kinematics that makes hands of a trace's joints
//! makes them of a headset's. Each world the stepper publishes goes back to the page, which
//! draws it in the headset's own stereo with the hand from its local joints (not delayed by
//! the round trip), or, in a browser without WebXR, as a spectator's orbit view.
//!
//! - [`server`]: HTTPS/WSS (or plain HTTP for `http://localhost`), the token, the socket per
//!   page, the clock offset per page; on tokio's threads, handing decoded messages to the stage
//!   through a bounded queue and an eventfd.
//! - [`service`]: the stage's [`common::node::Task`]: the joints published, the worlds sent
//!   back, the page's own timing recorded into the report.
//! - [`driving`]: which page drives the hand, its frames' order and time (the page's clock
//!   mapped to this machine's, held), and the gaps: pure, without sockets or the bus.
//! - [`scene`]: the scene message, made of the session's (the page's protocol itself is
//!   `webxr_wire::page`).
//! - [`console`]: what the terminal and the session's report are told.
//! - [`certificate`]: the self-signed certificate made on first use and kept for the next,
//!   its files the shared `keyfile` crate's (0600, no links followed, 0700 folders, renewed
//!   before it expires), as the zenoh link's keys are.
//! - [`driver`]: the emulated headset's browser driver (`handblocks emulate headset`).
//! - [`address`]: the URL to open (this machine's address on the network) and its QR code.

pub mod address;
pub mod certificate;
pub mod console;
pub mod driver;
pub mod driving;
pub mod page;
pub mod peers;
pub mod scene;
pub mod server;
pub mod service;

pub use service::{run, WebxrError};

common::process!(
    /// The webxr stage's process (a headset's page), as `handblocks service webxr` runs it.
    Webxr,
    WebxrError,
    service::run
);
