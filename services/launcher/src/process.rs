//! One child process of the session: started as `handblocks service NAME`, in its own process
//! group (so a Ctrl-C at the terminal reaches only the launcher, which then stops the set in
//! order), with a pipe on its standard input that the launcher closes to release it.

use std::path::Path;
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use std::os::unix::process::CommandExt;

use common::stage::Priority;
use common::Stage;

/// The nice value of the renderer and recorder processes (the pipeline's own run at 0).
const CONSUMER_NICE: libc::c_int = 10;

pub struct ServiceProcess {
    pub stage: Stage,
    child: Child,
    release: Option<ChildStdin>,
    pub exit: Option<ExitStatus>,
}

/// Starts `command`'s process on the CPUs `cpus` holds, when it holds any.
fn pin(command: &mut Command, cpus: Option<libc::cpu_set_t>) {
    if let Some(set) = cpus {
        // SAFETY: runs in the child between fork and exec; sched_setaffinity is one system
        // call on a set already built (no allocation, async-signal-safe). Every thread the
        // process starts inherits it. Failure leaves the child where it may already run.
        unsafe {
            command.pre_exec(move || {
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
                Ok(())
            });
        }
    }
}

impl ServiceProcess {
    pub fn start(
        exe: &Path,
        stage: Stage,
        session: &Path,
        bus_id: &str,
        extra: &[std::ffi::OsString],
        cpus: Option<libc::cpu_set_t>,
        env: &[(&str, &std::ffi::OsStr)],
    ) -> std::io::Result<ServiceProcess> {
        let mut command = Command::new(exe);
        command.envs(env.iter().copied());
        pin(&mut command, cpus);
        command
            .arg("service")
            .arg(stage.name())
            .arg("--session")
            .arg(session)
            .arg("--bus")
            .arg(bus_id)
            .args(extra);
        Self::spawn(stage, &mut command)
    }

    /// Starts a program of the user's as the stage `stage` (an `external` source: Python's
    /// `handblocks.Source`), with the session's bus id and file in its environment
    /// (`HANDBLOCKS_BUS`, `HANDBLOCKS_SESSION`, `HANDBLOCKS_STAGE`): it is released and stopped
    /// through its standard input as every service is.
    pub fn start_program(
        program: &[String],
        stage: Stage,
        session: &Path,
        bus_id: &str,
        cpus: Option<libc::cpu_set_t>,
    ) -> std::io::Result<ServiceProcess> {
        let (name, args) = program
            .split_first()
            .ok_or_else(|| std::io::Error::other("the command is empty"))?;
        let mut command = Command::new(name);
        pin(&mut command, cpus);
        command
            .args(args)
            .env("HANDBLOCKS_BUS", bus_id)
            .env("HANDBLOCKS_SESSION", session)
            .env("HANDBLOCKS_STAGE", stage.name());
        Self::spawn(stage, &mut command)
    }

    fn spawn(stage: Stage, command: &mut Command) -> std::io::Result<ServiceProcess> {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::inherit())
            .stderr(Stdio::inherit())
            .process_group(0)
            .spawn()?;
        // Consumers at the end of the pipeline must never delay the world: on a machine without
        // a GPU the renderer's software rasteriser would otherwise take the cores the stepper
        // needs. Lower their priority (their threads, started later, inherit it).
        // The renderer runs SCHED_IDLE: any pipeline stage that wakes takes the core at once,
        // and the renderer still gets every cycle the pipeline leaves. The recorder, light and
        // latency-free, runs at a lower nice value.
        // The stage table says which ([`Stage::priority`]).
        if stage.priority() != Priority::Normal {
            // SAFETY: setpriority/sched_setscheduler on our own child's pid with a valid param;
            // an unprivileged process may lower its own priority; failure only leaves the default.
            unsafe {
                libc::setpriority(libc::PRIO_PROCESS, child.id() as libc::id_t, CONSUMER_NICE);
                if stage.priority() == Priority::Idle {
                    let param = libc::sched_param { sched_priority: 0 };
                    libc::sched_setscheduler(child.id() as libc::pid_t, libc::SCHED_IDLE, &param);
                }
            }
        }
        let release = child.stdin.take();
        Ok(ServiceProcess {
            stage,
            child,
            release,
            exit: None,
        })
    }

    /// The exit status if the process has ended (reaping it).
    /// The CPU time the process has used so far (user + system, all its threads), from
    /// /proc; None once it is reaped or where /proc cannot tell.
    pub fn cpu_seconds(&self) -> Option<f64> {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", self.child.id())).ok()?;
        // The name in parentheses may hold spaces: the fields follow its last ')'.
        let fields: Vec<&str> = stat
            .get(stat.rfind(')')? + 1..)?
            .split_whitespace()
            .collect();
        // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name.
        let ticks: u64 =
            fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
        // SAFETY: sysconf has no preconditions.
        let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
        (hz > 0).then(|| ticks as f64 / hz as f64)
    }

    pub fn poll_exit(&mut self) -> Option<ExitStatus> {
        if self.exit.is_none() {
            if let Ok(Some(status)) = self.child.try_wait() {
                self.exit = Some(status);
            }
        }
        self.exit
    }

    /// Lets every thread of the running process use the CPUs this process may use (undoing
    /// its placement, when the renderer it was placed apart from did not start).
    pub fn unpin(&mut self) {
        if self.poll_exit().is_some() {
            return;
        }
        // SAFETY: sched_getaffinity writes one cpu_set_t into the valid pointer; sched_setaffinity
        // reads one. A thread that ended meanwhile makes the call fail, which is harmless.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
                return;
            }
            let tasks = format!("/proc/{}/task", self.child.id());
            for task in std::fs::read_dir(tasks).into_iter().flatten().flatten() {
                if let Ok(tid) = task.file_name().to_string_lossy().parse::<libc::pid_t>() {
                    libc::sched_setaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &set);
                }
            }
        }
    }

    /// Asks the process to stop (SIGTERM): it drains its inputs and sends its final report.
    pub fn request_stop(&mut self) {
        if self.poll_exit().is_none() {
            // SAFETY: plain kill(2) on our own child's pid, which we have not reaped yet.
            unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        }
    }

    /// Lets the process exit (closes its standard input) and reaps it, killing it if it has not
    /// exited within `limit`. Returns its exit status.
    pub fn release_and_reap(&mut self, limit: Duration) -> Option<ExitStatus> {
        drop(self.release.take());
        let start = Instant::now();
        while self.poll_exit().is_none() {
            if start.elapsed() > limit {
                let _ = self.child.kill();
                self.exit = self.child.wait().ok();
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        self.exit
    }
}

impl Drop for ServiceProcess {
    fn drop(&mut self) {
        // Never leave a child behind, whatever path the launcher took.
        if self.poll_exit().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
