//! How busy the machine was while a session ran, apart from the session itself: so that a
//! budget broken on a loaded machine says so, and a person does not chase the pipeline for
//! what another process (a build, a browser, a noisy VM neighbour) did.
//!
//! Two readings of `/proc/stat` (every CPU's busy time) and of `getrusage` (this launcher and
//! every child it reaped: the session's processes), one before the processes start and one
//! after they are reaped. What the machine was busy with beyond what the session used is the
//! others' share; the hypervisor's `steal` (time a virtual CPU was ready but not run) is
//! counted apart, since no process here can be blamed for it. No reading is taken while the
//! session runs, so this costs the pipeline nothing.

use std::time::Instant;

/// A share of the machine that others took, above which the verdict says the machine looked
/// loaded: a fifth of its CPUs' time. A quiet desktop's background stays well under it (a few
/// per cent); a build or a second session is far over it.
pub const LOADED_FRACTION: f64 = 0.2;

/// One reading, taken at a moment.
#[derive(Debug, Clone, Copy)]
pub struct CpuReading {
    at: Instant,
    /// Every CPU's busy time (user, nice, system, irq, softirq), seconds.
    busy_s: f64,
    /// Every CPU's steal time, seconds.
    steal_s: f64,
    /// This process and its reaped children, user + system, seconds.
    ours_s: f64,
}

/// What others did with the machine over a session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineLoad {
    /// The CPUs the machine has (what the fractions are of).
    pub cpus: usize,
    /// Wall time between the two readings, seconds.
    pub seconds: f64,
    /// CPU time used by processes other than the session's, seconds.
    pub others_cpu_s: f64,
    /// CPU time the hypervisor gave to others while our virtual CPUs waited, seconds.
    pub steal_s: f64,
    /// CPU time the session's own processes used, seconds.
    pub session_cpu_s: f64,
}

impl MachineLoad {
    /// The others' share of the machine's CPU time (steal included), 0 to 1.
    pub fn others_fraction(&self) -> f64 {
        let capacity = self.seconds * self.cpus.max(1) as f64;
        if capacity <= 0.0 {
            return 0.0;
        }
        ((self.others_cpu_s + self.steal_s) / capacity).clamp(0.0, 1.0)
    }

    /// Whether others took more than [`LOADED_FRACTION`] of the machine.
    pub fn looked_loaded(&self) -> bool {
        self.others_fraction() > LOADED_FRACTION
    }

    /// `other processes used 0.83 of this machine's 2 CPU(s) over the 4.2 s, while the
    /// session's own used 1.10`.
    pub fn describe(&self) -> String {
        let per_s = |x: f64| {
            if self.seconds > 0.0 {
                x / self.seconds
            } else {
                0.0
            }
        };
        let steal = if self.steal_s > 0.0 {
            format!(
                ", and the hypervisor took {:.2} (steal)",
                per_s(self.steal_s)
            )
        } else {
            String::new()
        };
        format!(
            "other processes used {:.2} of this machine's {} CPU(s) over the {:.1} s{steal}, while \
             the session's own used {:.2}",
            per_s(self.others_cpu_s),
            self.cpus,
            self.seconds,
            per_s(self.session_cpu_s)
        )
    }
}

impl CpuReading {
    /// A reading now; None where `/proc/stat` cannot be read (not Linux, a sandbox).
    pub fn now() -> Option<CpuReading> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let (busy_s, steal_s) = parse_cpu_line(&stat, clock_ticks()?)?;
        Some(CpuReading {
            at: Instant::now(),
            busy_s,
            steal_s,
            ours_s: own_and_children_cpu_s(),
        })
    }

    /// What others did between `self` and `later`, on a machine of `cpus` CPUs.
    pub fn load_until(&self, later: &CpuReading, cpus: usize) -> MachineLoad {
        let session_cpu_s = (later.ours_s - self.ours_s).max(0.0);
        MachineLoad {
            cpus,
            seconds: later.at.duration_since(self.at).as_secs_f64(),
            others_cpu_s: ((later.busy_s - self.busy_s) - session_cpu_s).max(0.0),
            steal_s: (later.steal_s - self.steal_s).max(0.0),
            session_cpu_s,
        }
    }
}

fn clock_ticks() -> Option<f64> {
    // SAFETY: sysconf reads a constant of the system; no pointer is involved.
    let ticks = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    (ticks > 0).then_some(ticks as f64)
}

/// The first line of `/proc/stat` (`cpu  user nice system idle iowait irq softirq steal ...`,
/// in clock ticks) as (busy, steal) seconds.
fn parse_cpu_line(stat: &str, ticks_per_s: f64) -> Option<(f64, f64)> {
    let line = stat.lines().find(|l| l.starts_with("cpu "))?;
    let fields: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .map(|f| f.parse().ok())
        .collect::<Option<_>>()?;
    let at = |i: usize| fields.get(i).copied().unwrap_or(0);
    // user nice system [idle iowait] irq softirq; guest time is already inside user.
    let busy = at(0) + at(1) + at(2) + at(5) + at(6);
    Some((busy as f64 / ticks_per_s, at(7) as f64 / ticks_per_s))
}

fn own_and_children_cpu_s() -> f64 {
    let used = |who| {
        // SAFETY: getrusage writes one rusage into the zeroed struct it is handed.
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        if unsafe { libc::getrusage(who, &mut u) } != 0 {
            return 0.0;
        }
        let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 / 1e6;
        t(u.ru_utime) + t(u.ru_stime)
    };
    used(libc::RUSAGE_SELF) + used(libc::RUSAGE_CHILDREN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cpu_line_gives_busy_and_steal_seconds() {
        let stat = "cpu  100 20 30 5000 40 5 5 8 0 0\ncpu0 50 10 15 2500 20 2 3 4 0 0\n";
        let (busy, steal) = parse_cpu_line(stat, 100.0).unwrap();
        assert!((busy - 1.6).abs() < 1e-9, "{busy}");
        assert!((steal - 0.08).abs() < 1e-9, "{steal}");
        assert!(parse_cpu_line("cpu0 1 2 3\n", 100.0).is_none());
        assert!(parse_cpu_line("cpu  1 x 3\n", 100.0).is_none());
    }

    #[test]
    fn others_are_what_the_machine_did_beyond_the_session() {
        let load = MachineLoad {
            cpus: 2,
            seconds: 10.0,
            others_cpu_s: 6.0,
            steal_s: 0.0,
            session_cpu_s: 9.0,
        };
        assert!((load.others_fraction() - 0.3).abs() < 1e-9);
        assert!(load.looked_loaded());
        let quiet = MachineLoad {
            others_cpu_s: 0.4,
            ..load
        };
        assert!(!quiet.looked_loaded());
        assert!(quiet.describe().contains("0.04 of this machine's 2 CPU(s)"));
    }

    #[test]
    fn two_readings_here_measure_something_sane() {
        let Some(a) = CpuReading::now() else { return };
        let mut x = 0u64;
        for i in 0..2_000_000u64 {
            x = x.wrapping_mul(31).wrapping_add(i);
        }
        std::hint::black_box(x);
        let b = CpuReading::now().unwrap();
        let load = a.load_until(&b, 2);
        assert!(load.seconds >= 0.0 && load.others_cpu_s >= 0.0 && load.steal_s >= 0.0);
        assert!((0.0..=1.0).contains(&load.others_fraction()));
    }
}
