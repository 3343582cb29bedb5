//! Which CPUs each process of a session may run on.
//!
//! With a software rasteriser (no GPU), the renderer keeps every core busy. Running it
//! `SCHED_IDLE` is not enough: measured on a 2-vCPU VM at 120 Hz, the stepper's origin -> world
//! p99 was 3.8-5.3 ms beside the renderer and 0.30-0.51 ms with the renderer on a CPU of its
//! own, at the same 90 frames a second (README, "Latency"). A woken pipeline stage must wait
//! for the renderer's thread to reach a preemption point, and on a VM for the hypervisor too;
//! on a CPU of its own nothing is in its way.
//!
//! So when a session renders and the machine has two CPUs or more, the pipeline (source,
//! kinematics, stepper) gets the first quarter of the CPUs this process may use (at least one)
//! and the consumers (renderer, recorder) get the rest. An external source (a program of the
//! user's, often a tracker running a neural network) goes with the consumers, where the
//! renderer yields to it. `[renderer] own_cpus = false` turns it off. Without a renderer
//! nothing is pinned.

use common::stage::Cores;
use common::Stage;

/// The CPU sets of the two groups; `None` when nothing is pinned.
#[derive(Clone, Copy)]
pub struct Placement {
    sets: Option<(libc::cpu_set_t, libc::cpu_set_t)>,
    pub pipeline_cpus: usize,
    pub consumer_cpus: usize,
}

/// How many of `n` CPUs go to the pipeline when the consumers get their own.
pub fn pipeline_share(n: usize) -> usize {
    (n / 4).max(1)
}

fn cpu_set(cpus: &[usize]) -> libc::cpu_set_t {
    // SAFETY: cpu_set_t is a plain bit array; all zeroes is the empty set, and CPU_SET only
    // writes bits below CPU_SETSIZE (our CPUs come from sched_getaffinity, so they are).
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for &c in cpus {
            libc::CPU_SET(c, &mut set);
        }
        set
    }
}

impl Placement {
    /// No pinning: every process may run anywhere this one may.
    pub fn shared() -> Placement {
        Placement {
            sets: None,
            pipeline_cpus: 0,
            consumer_cpus: 0,
        }
    }

    /// The placement for a session that renders (`separate` = `[renderer] own_cpus`).
    pub fn for_session(renders: bool, separate: bool) -> Placement {
        if !(renders && separate) {
            return Placement::shared();
        }
        // SAFETY: sched_getaffinity writes one cpu_set_t into the valid pointer we pass;
        // CPU_ISSET reads it.
        let allowed: Vec<usize> = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
                return Placement::shared();
            }
            (0..libc::CPU_SETSIZE as usize)
                .filter(|&c| libc::CPU_ISSET(c, &set))
                .collect()
        };
        if allowed.len() < 2 {
            return Placement::shared();
        }
        let (pipeline, consumers) = allowed.split_at(pipeline_share(allowed.len()));
        Placement {
            sets: Some((cpu_set(pipeline), cpu_set(consumers))),
            pipeline_cpus: pipeline.len(),
            consumer_cpus: consumers.len(),
        }
    }

    /// The CPU set of a stage's process, if it is pinned.
    pub fn cpus_of(&self, stage: Stage) -> Option<libc::cpu_set_t> {
        let (pipeline, consumers) = self.sets?;
        // The stage table says which share each stage is on ([`Stage::cores`]).
        Some(match stage.cores() {
            Cores::Consumers => consumers,
            Cores::Pipeline => pipeline,
        })
    }

    /// One line for the user, when something is pinned.
    pub fn describe(&self) -> Option<String> {
        self.sets.map(|_| {
            format!(
                "pipeline on {} CPU(s), renderer and recorder on the other {} \
                 ([renderer] own_cpus = false to share them)",
                self.pipeline_cpus, self.consumer_cpus
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pipeline_gets_a_quarter_and_at_least_one() {
        assert_eq!(pipeline_share(2), 1);
        assert_eq!(pipeline_share(4), 1);
        assert_eq!(pipeline_share(8), 2);
        assert_eq!(pipeline_share(16), 4);
    }

    #[test]
    fn nothing_is_pinned_without_a_renderer_or_when_asked() {
        assert!(Placement::for_session(false, true)
            .cpus_of(Stage::Stepper)
            .is_none());
        assert!(Placement::for_session(true, false)
            .cpus_of(Stage::Renderer)
            .is_none());
    }
}
