//! handblocks benchmarks. Machines here are shared and noisy, so every figure is reported next
//! to a peer measured in the same run, and judged as a ratio to it.
//!
//! * [`latency`]: the whole process set against a bare two-process iceoryx2 hop.
//! * [`load`]: the pipeline at 1 kHz for a minute, every topic recorded: the flow and latency.
//! * [`accuracy`]: the paper model and the precise one (rapier3d) against exact answers, and
//!   what each setting costs per step, measured in the same run.
//! * [`hard_cases`]: the hard-case table, harness and criteria, shared by [`stability`] and the
//!   suite (`tests/hard_suite.rs`, `tests/far_from_origin.rs`, `tests/r14.rs`).
//! * [`stability`]: every hard case under both models, with its figures.
//! * [`stepper`]: a step's cost against the world's size, and each effect's cost on and off.
//! * [`netem`]: a userspace UDP proxy that delays and drops, for shared worlds under a bad network.
//! * [`shared`]: a shared world under a bad network (host and participants behind [`netem`] proxies).
//! * [`plot`]: the figures (plotters into a PNG), shared by the reports.
//! * [`page`]: the head of each report's markdown page (what, how to read it, where from).

pub mod accuracy;
pub mod hands;
pub mod hard_cases;
pub mod hgrm;
pub mod latency;
pub mod load;
pub mod netem;
pub mod page;
pub mod plot;
pub mod shared;
pub mod stability;
pub mod stepper;
pub mod tosses;
pub mod transport;
