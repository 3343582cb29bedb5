//! A pseudo-terminal pair: the emulated device holds the master side, the driver opens the
//! slave path (`/dev/pts/N`) exactly as it would open `/dev/ttyUSB0`.

use std::ffi::CStr;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::PathBuf;

/// Both ends of a pty. The slave fd is kept open by the emulator so the pty survives the
/// driver closing and reopening it (as a real serial port does), and so the master never
/// reads end-of-file between driver sessions.
pub struct Pty {
    pub master: OwnedFd,
    _slave: OwnedFd,
    /// The slave device, e.g. `/dev/pts/7`.
    pub path: PathBuf,
}

impl Pty {
    /// Opens a pty pair, puts the line in raw mode (no echo, no CR/LF translation, no
    /// control-C signal: a device's bytes pass unchanged) and makes the master non-blocking.
    pub fn open() -> io::Result<Pty> {
        let mut master: libc::c_int = -1;
        let mut slave: libc::c_int = -1;
        // SAFETY: valid out-pointers; null name/termios/winsize are allowed.
        let rc = unsafe {
            libc::openpty(
                &mut master,
                &mut slave,
                std::ptr::null_mut(),
                std::ptr::null(),
                std::ptr::null(),
            )
        };
        if rc != 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: openpty succeeded, so both are fresh fds we now own.
        let (master, slave) =
            unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
        for fd in [master.as_raw_fd(), slave.as_raw_fd()] {
            // SAFETY: fcntl on an fd we own.
            unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) };
        }
        // SAFETY: termios is plain data; tcgetattr fills it.
        let mut t: libc::termios = unsafe { std::mem::zeroed() };
        // SAFETY: valid fd and pointer.
        if unsafe { libc::tcgetattr(slave.as_raw_fd(), &mut t) } != 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: valid pointer.
        unsafe { libc::cfmakeraw(&mut t) };
        // SAFETY: valid fd and pointer.
        if unsafe { libc::tcsetattr(slave.as_raw_fd(), libc::TCSANOW, &t) } != 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: fcntl on an fd we own.
        let flags = unsafe { libc::fcntl(master.as_raw_fd(), libc::F_GETFL) };
        // SAFETY: as above.
        if flags < 0
            || unsafe { libc::fcntl(master.as_raw_fd(), libc::F_SETFL, flags | libc::O_NONBLOCK) }
                < 0
        {
            return Err(io::Error::last_os_error());
        }
        let mut name = [0 as libc::c_char; 128];
        // SAFETY: the buffer and its length are valid.
        let rc = unsafe { libc::ptsname_r(master.as_raw_fd(), name.as_mut_ptr(), name.len()) };
        if rc != 0 {
            return Err(io::Error::from_raw_os_error(rc));
        }
        // SAFETY: ptsname_r wrote a NUL-terminated string into the buffer.
        let path = unsafe { CStr::from_ptr(name.as_ptr()) }
            .to_string_lossy()
            .into_owned();
        Ok(Pty {
            master,
            _slave: slave,
            path: PathBuf::from(path),
        })
    }

    /// Waits up to `timeout_ms` for bytes from the driver.
    pub fn wait_readable(&self, timeout_ms: i32) -> io::Result<bool> {
        let mut pfd = libc::pollfd {
            fd: self.master.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd.
        let rc = unsafe { libc::poll(&mut pfd, 1, timeout_ms) };
        if rc < 0 {
            let e = io::Error::last_os_error();
            if e.kind() == io::ErrorKind::Interrupted {
                return Ok(false);
            }
            return Err(e);
        }
        Ok(rc > 0 && pfd.revents & libc::POLLIN != 0)
    }

    /// Non-blocking read; Ok(0) when nothing is there.
    pub fn read(&self, buf: &mut [u8]) -> io::Result<usize> {
        // SAFETY: buffer pointer and length are valid.
        let n = unsafe { libc::read(self.master.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
        if n < 0 {
            let e = io::Error::last_os_error();
            return match e.kind() {
                io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted => Ok(0),
                _ => Err(e),
            };
        }
        Ok(n as usize)
    }

    /// Non-blocking write of as much as the line takes; the rest is dropped, as a device's
    /// UART would drop what nobody reads.
    pub fn write(&self, mut bytes: &[u8]) -> usize {
        let mut written = 0;
        while !bytes.is_empty() {
            // SAFETY: buffer pointer and length are valid.
            let n =
                unsafe { libc::write(self.master.as_raw_fd(), bytes.as_ptr().cast(), bytes.len()) };
            if n <= 0 {
                break;
            }
            written += n as usize;
            bytes = &bytes[n as usize..];
        }
        written
    }
}
