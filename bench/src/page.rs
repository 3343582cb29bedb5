//! The head of every benchmark's markdown page: its title, what it measures and how to read
//! it, and where the figures come from (the command that wrote the page, when, at which commit,
//! on what machine, whether it was a quick run).
//!
//! Why: the pages under `docs/bench/` are read by people who did not run them, months later,
//! beside figures from other machines. A number without its machine and commit cannot be
//! compared with anything, and a regenerated page must say by itself how to regenerate it.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// Where a run's figures come from.
#[derive(Debug, Clone)]
pub struct Provenance {
    /// The command line that wrote the page, as typed (the executable named `handblocks`).
    pub command: String,
    /// `YYYY-MM-DD HH:MM UTC`.
    pub date_utc: String,
    /// `git rev-parse --short HEAD` in the working directory, and whether the tree had
    /// uncommitted changes (outside the output folder); "unknown" outside a checkout.
    pub commit: String,
    /// The CPU model (`/proc/cpuinfo`) and the CPUs this process may use.
    pub machine: String,
    pub quick: bool,
    /// How quiet the machine was ([`Quietness::line`]), where the bench measured it.
    pub quietness: Option<String>,
}

impl Provenance {
    /// This process's: its command line, now, the checkout it runs in, this machine.
    /// `out_dir` is left out of the "uncommitted changes" check (the run rewrites it).
    pub fn of_this_run(quick: bool, out_dir: &Path) -> Provenance {
        Provenance {
            command: command_line(),
            date_utc: utc_now(),
            commit: commit(out_dir),
            machine: machine(),
            quick,
            quietness: None,
        }
    }

    /// The same, with how quiet the machine was since `q` started.
    pub fn with_quietness(mut self, q: &Quietness) -> Provenance {
        self.quietness = Some(q.line());
        self
    }
}

/// How busy the machine was with other work during a run: the CPU time every process used
/// (`/proc/stat`) less this process's and its waited-for children's (`getrusage`), and the
/// time the hypervisor took (steal). A latency figure from a machine that was doing something
/// else is not the machine's.
pub struct Quietness {
    started: std::time::Instant,
    busy_s: f64,
    steal_s: f64,
    own_s: f64,
}

impl Quietness {
    pub fn start() -> Quietness {
        let (busy_s, steal_s) = machine_cpu_s();
        Quietness {
            started: std::time::Instant::now(),
            busy_s,
            steal_s,
            own_s: own_cpu_s(),
        }
    }

    /// "other processes 1.2 CPU-s in 605 s (0.1 % of 2 CPUs); steal 0.0 %".
    pub fn line(&self) -> String {
        let (busy_s, steal_s) = machine_cpu_s();
        let wall = self.started.elapsed().as_secs_f64();
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
        let others = ((busy_s - self.busy_s) - (own_cpu_s() - self.own_s)).max(0.0);
        let share = |x: f64| {
            if wall > 0.0 {
                100.0 * x / (wall * cpus)
            } else {
                0.0
            }
        };
        format!(
            "other processes {others:.1} CPU-s in {wall:.0} s ({:.1} % of {cpus:.0} CPUs); \
             steal {:.1} %",
            share(others),
            share(steal_s - self.steal_s)
        )
    }
}

/// Every CPU's busy time (user, nice, system, irq, softirq) and steal, seconds, since boot.
fn machine_cpu_s() -> (f64, f64) {
    let text = std::fs::read_to_string("/proc/stat").unwrap_or_default();
    let fields: Vec<f64> = text
        .lines()
        .next()
        .unwrap_or("")
        .split_whitespace()
        .skip(1)
        .filter_map(|x| x.parse().ok())
        .collect();
    // SAFETY: sysconf reads a constant.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    let at = |i: usize| fields.get(i).copied().unwrap_or(0.0);
    ((at(0) + at(1) + at(2) + at(5) + at(6)) / hz, at(7) / hz)
}

/// This process's CPU time and its waited-for children's, seconds.
fn own_cpu_s() -> f64 {
    let of = |who| {
        // SAFETY: getrusage fills the struct on the stack.
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        unsafe { libc::getrusage(who, &mut u) };
        let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
        t(u.ru_utime) + t(u.ru_stime)
    };
    of(libc::RUSAGE_SELF) + of(libc::RUSAGE_CHILDREN)
}

/// The arguments, quoted for a shell where needed, after `handblocks`.
fn command_line() -> String {
    let mut words = vec!["handblocks".to_string()];
    words.extend(std::env::args().skip(1).map(|a| {
        if !a.is_empty()
            && a.chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_./=:,@+".contains(c))
        {
            a
        } else {
            format!("'{}'", a.replace('\'', "'\\''"))
        }
    }));
    words.join(" ")
}

/// Days since 1970-01-01 to a civil date (Howard Hinnant's algorithm): the crate has no
/// calendar dependency, and a date is all a page needs.
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    let (y, m, d) = civil_from_days(secs.div_euclid(86_400));
    let s = secs.rem_euclid(86_400);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02} UTC",
        s / 3600,
        s % 3600 / 60
    )
}

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn commit(out_dir: &Path) -> String {
    let Some(head) = git(&["rev-parse", "--short", "HEAD"]).filter(|h| !h.is_empty()) else {
        return "unknown (not run in a git checkout)".into();
    };
    let status = |pathspec: &[&str]| {
        let mut args = vec!["status", "--porcelain", "--untracked-files=no", "--"];
        args.extend_from_slice(pathspec);
        git(&args)
    };
    // An output folder outside the checkout is no pathspec git takes: then the whole tree.
    let exclude = format!(":(exclude){}", out_dir.display());
    let dirty = status(&[".", &exclude])
        .or_else(|| status(&["."]))
        .is_some_and(|s| !s.is_empty());
    if dirty {
        format!("{head} with uncommitted changes")
    } else {
        head
    }
}

fn machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.split_whitespace().collect::<Vec<_>>().join(" "))
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{model}, {cpus} CPUs available to the run")
}

/// The page's head: `# title`, the paragraph saying what is measured and how to read it, and
/// the run's provenance as a short list. `what` is markdown.
pub fn head(title: &str, what: &str, p: &Provenance) -> String {
    let mut s = format!("# {title}\n\n{what}\n\n");
    let _ = writeln!(s, "- command: `{}`", p.command);
    let _ = writeln!(
        s,
        "- run: {}",
        if p.quick {
            "**quick** (`--quick`: a reduced run, as said above; the full run drops the flag)"
        } else {
            "full"
        }
    );
    let _ = writeln!(s, "- when: {}", p.date_utc);
    let _ = writeln!(s, "- commit: {}", p.commit);
    let _ = writeln!(s, "- machine: {}", p.machine);
    if let Some(q) = &p.quietness {
        let _ = writeln!(s, "- how quiet: {q}");
    }
    s.push('\n');
    s
}

/// The figure, embedded: `![alt](file)` (the PNG beside the page).
pub fn figure(alt: &str, file: &str) -> String {
    format!("![{alt}]({file})\n\n")
}

/// A figure in a page's JSON: the number, or null where it is not finite (JSON has no NaN).
pub fn num(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn days_become_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(civil_from_days(19_723), (2024, 1, 1));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }

    #[test]
    fn a_head_names_its_run() {
        let p = Provenance {
            command: "handblocks bench stepper --quick".into(),
            date_utc: "2024-01-01 00:00 UTC".into(),
            commit: "abc1234".into(),
            machine: "a CPU, 2 CPUs available to the run".into(),
            quick: true,
            quietness: None,
        };
        let h = head("T", "What.", &p);
        assert!(h.starts_with("# T\n\nWhat.\n\n"));
        for needle in [
            "`handblocks bench stepper --quick`",
            "**quick**",
            "abc1234",
            "2 CPUs",
        ] {
            assert!(h.contains(needle), "{needle}: {h}");
        }
    }
}
