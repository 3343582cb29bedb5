//! The real hand devices: a CyberGlove ([`cyberglove`]) and a Polhemus FASTRAK ([`fastrak`]),
//! each on a serial port ([`serial`]).
//!
//! Each driver is split in two so that the byte-level logic is testable without a tty:
//! a pure parser (bytes in, records out, resynchronising on damage) and a driver that owns the
//! link, speaks the command protocol, and turns records into the project's samples.
//!
//! Errors never end a driver once it is open: a device that stops answering, or a cable that is
//! pulled, is reported as a [`DeviceError`] from `read` and the driver reconnects with backoff on
//! the following calls. Only `open` (and `Glove::new`/`Tracker::new` for configuration) fails for
//! good, because what it reports — a wrong port, a calibration file that does not fit, a glove
//! of another size — needs a person to change the configuration.
//!
//! How the acquisition process uses it, for `[source] kind = "devices"`:
//!
//! ```text
//! // The settings were read and checked with the session (common::config::devices).
//! let Source::Devices { glove, tracker } = &session.source else { ... };
//! let epoch = monotonic_ns();                                  // one timeline for both
//! let gc = GloveConfig { epoch_ns: epoch, ..glove.clone() };
//! let tc = TrackerConfig { epoch_ns: epoch, ..tracker.clone() };
//! let readers = DeviceReaders::spawn(Some(Glove::open(gc)?), Some(Tracker::open(tc)?))?;
//! while !shutdown::requested() {
//!     match readers.recv_timeout(Duration::from_millis(50)) {
//!         Some(DeviceEvent::Glove(g)) => glove_outlet.publish(&g)?,
//!         Some(DeviceEvent::Tracker(t)) => tracker_outlet.publish(&t)?,
//!         Some(DeviceEvent::Error(e)) => eprintln!("acquisition: {e}"),   // it reconnects
//!         None => {}
//!     }
//! }
//! let stats = readers.stop();
//! ```

pub mod calibration;
pub mod cyberglove;
mod error;
pub mod fastrak;
mod link_loop;
pub mod readers;
pub mod serial;

pub use calibration::{Calibration, CalibrationError};
pub use cyberglove::{Glove, GloveConfig, GloveMode, GloveParser};
pub use error::DeviceError;
pub use fastrak::{FastrakParser, Format, Orientation, Tracker, TrackerConfig, TrackerMode, Units};
pub use readers::{DeviceEvent, DeviceReaders, ReaderStats};
pub use serial::LinkSettings;
pub use serial::LinkStats;

/// What one `read` call produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadOutcome {
    /// The output sample was filled with a new, valid reading.
    Sample,
    /// Nothing new within this call's time slice (the device is between samples, or the
    /// driver is waiting to retry a connection). Call again; the output was not touched.
    Pending,
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use common::config::session::Source;
    use common::config::Session;

    use super::{Glove, Tracker};

    /// The example devices session, as session loading reads it, gives settings both drivers
    /// take (its calibration file included).
    #[test]
    fn the_example_sessions_settings_make_drivers() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/devices/emulated-session.toml");
        let session = Session::load(&file).unwrap();
        let Source::Devices { glove, tracker } = session.source else {
            panic!("not a devices session: {:?}", session.source)
        };
        assert!(Glove::new(*glove).is_ok());
        assert!(Tracker::new(*tracker).is_ok());
    }
}
