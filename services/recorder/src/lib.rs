//! The recorder: writes every sample of every topic to an MCAP file
//! ([`recording`]) and counts, per topic, what it missed (gaps in seq).

pub mod service;
