//! One child process of the session: started as `handblocks service NAME`, in its own process
//! group (so a Ctrl-C at the terminal reaches only the launcher, which then stops the set in
//! order), with a pipe on its standard input that the launcher closes to release it.

use std::path::Path;
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use std::os::unix::process::CommandExt;

use common::Stage;

pub struct ServiceProcess {
    pub stage: Stage,
    child: Child,
    release: Option<ChildStdin>,
    pub exit: Option<ExitStatus>,
}

impl ServiceProcess {
    pub fn start(
        exe: &Path,
        stage: Stage,
        session: &Path,
        bus_id: &str,
    ) -> std::io::Result<ServiceProcess> {
        let mut child = Command::new(exe)
            .arg("service")
            .arg(stage.name())
            .arg("--session")
            .arg(session)
            .arg("--bus")
            .arg(bus_id)
            .stdin(Stdio::piped())
            .stdout(Stdio::inherit())
            .stderr(Stdio::inherit())
            .process_group(0)
            .spawn()?;
        let release = child.stdin.take();
        Ok(ServiceProcess {
            stage,
            child,
            release,
            exit: None,
        })
    }

    /// The exit status if the process has ended (reaping it).
    pub fn poll_exit(&mut self) -> Option<ExitStatus> {
        if self.exit.is_none() {
            if let Ok(Some(status)) = self.child.try_wait() {
                self.exit = Some(status);
            }
        }
        self.exit
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
