//! The stamp every sample starts with, and the one clock all processes share.

use iceoryx2::prelude::ZeroCopySend;

/// Where a sample came from and when, carried through every stage.
///
/// * `seq` counts the samples of one topic from 0; a gap is a dropped sample.
/// * `source_time_ns` is the sample's time in its source's own timeline (device time, or the
///   time recorded in a trace). The stepper's simulated time follows it, never a wall clock,
///   which is what makes a replay bit-identical to the live run.
/// * `origin_ns` is CLOCK_MONOTONIC when the source sample entered the pipeline. Every stage
///   copies it from its input (the oldest, if it has several), so `publish_ns - origin_ns` at any
///   stage is the age of the data it just published.
/// * `publish_ns` is CLOCK_MONOTONIC just before this sample was sent; the receiver's clock
///   minus it is the hop latency.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("handblocks::Stamp")]
pub struct Stamp {
    pub seq: u64,
    pub source_time_ns: u64,
    pub origin_ns: u64,
    pub publish_ns: u64,
}

impl Stamp {
    /// A stamp for a sample that enters the pipeline now.
    pub fn at_origin(seq: u64, source_time_ns: u64) -> Self {
        let now = monotonic_ns();
        Stamp {
            seq,
            source_time_ns,
            origin_ns: now,
            publish_ns: now,
        }
    }

    /// A stamp for a sample derived from `input`: same source time and origin, new seq.
    pub fn derived(seq: u64, input: &Stamp) -> Self {
        Stamp {
            seq,
            source_time_ns: input.source_time_ns,
            origin_ns: input.origin_ns,
            publish_ns: 0,
        }
    }
}

/// The largest step of a source's clock between two of its samples that is still time
/// passing (a device dropout, a pause in a trace): 10 s, 1,200 steps at 120 Hz. A larger step
/// either way is a discontinuity (a clock reset, a damaged or edited trace: one changed
/// timestamp in a CARL file put a sample 60 years ahead), and nothing may try to catch up on
/// it: the replay re-times the samples after it, the stepper's timeline takes one step for it.
pub const MAX_SOURCE_GAP_NS: u64 = 10_000_000_000;

/// CLOCK_MONOTONIC in nanoseconds: one clock for every process of a machine.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` (absolute, so periodic loops do not drift).
/// Returns early if a signal arrives; callers re-check their stop flag and sleep again.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: valid timespec, null remainder is allowed with TIMER_ABSTIME.
    unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        )
    };
}

/// A sample type that starts with a [`Stamp`]; the topic table ([`crate::topic`]) implements
/// it for each topic's sample type. Here, below the topics and the bus, so that the layers of
/// the contract import only downwards: stamp <- samples <- topic <- config <- bus.
pub trait Stamped: Copy + std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + 'static {
    fn stamp(&self) -> &Stamp;
    fn stamp_mut(&mut self) -> &mut Stamp;
}
