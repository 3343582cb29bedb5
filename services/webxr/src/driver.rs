//! The emulated headset's browser driver (`handblocks emulate headset`): a Node.js script that
//! opens a session's page in headless Chromium with IWER (Meta's WebXR emulation runtime) as
//! its XR runtime and plays a recorded hand through the page's WebXR calls. Carried in the
//! binary, written to a temporary file and run with Node.js when asked; its modules
//! (playwright-core, iwer) are installed into target/ by scripts/webxr-tools.sh, never
//! committed.

/// The driver's source.
pub const HEADSET_JS: &str = include_str!("../driver/headset.js");
