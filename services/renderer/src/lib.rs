//! The renderer: draws the newest world state at the session's frame rate and measures how old
//! each frame's data is when its pixels are done (origin -> photon).
//!
//! Drawing (wgpu, off-axis stereo) is issue 6; this process already has the real timing
//! structure: it takes every `world` sample as it arrives (so the hop latency is the bus's, not
//! the frame pacing's), keeps only the newest, and at each frame deadline "renders" it and
//! publishes frame statistics. It never blocks upstream.

pub mod service;
