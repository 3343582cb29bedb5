//! The Polhemus FASTRAK: up to four receivers ("stations"), 120 records a second shared among
//! the active ones, over RS-232.
//!
//! The protocol, as far as this driver uses it (single-character commands, except `O`, which
//! ends with a carriage return):
//! * `c` / `C`: continuous output off / on; `P`: one record per active station.
//! * `F` / `f`: ASCII / binary records. `U` / `u`: inches / centimetres.
//! * `O<station>,<item>,<item>,...\r`: the output list of a station. Items used here:
//!   0 a space, 1 CR LF, 2 position x y z, 4 Euler angles (azimuth, elevation, roll, degrees),
//!   11 orientation quaternion (q0 = w, q1, q2, q3).
//! * Every record starts with `0`, the station number (`1`..`4`, ASCII in both formats) and an
//!   error character (a space when all is well), then the items in list order. ASCII items are
//!   signed decimal fields (`Sxxx.xx` for positions and angles, `Sx.xxxx` for quaternion
//!   components, separated by blanks); binary items are IEEE-754 single floats, least
//!   significant byte first. The driver always ends the list with item 1 (CR LF), which frames
//!   the ASCII records and is one more check on the binary ones.
//!
//! The module is in three parts, by concept: [`parser`] turns bytes into records (binary and
//! ASCII, Euler angles or quaternions), [`frame`] turns a record into the wrist's pose in the
//! world, and [`driver`] owns the link (open, configure, the read loop). The settings are the
//! session's ([`common::config::devices`]), re-exported here.

pub mod driver;
pub mod frame;
pub mod parser;

pub use common::config::devices::{Format, Orientation, TrackerConfig, TrackerMode, Units};
pub use driver::Tracker;
pub use frame::{record_to_world, tracker_axes, TrackerRecord};
pub use parser::{encode_record, item, FastrakParser};
