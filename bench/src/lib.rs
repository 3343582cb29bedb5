//! handblocks benchmarks. Machines here are shared and noisy, so every figure is reported next
//! to a peer measured in the same run, and judged as a ratio to it.
//!
//! * [`latency`]: the whole process set against a bare two-process iceoryx2 hop.

pub mod latency;
