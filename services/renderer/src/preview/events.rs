//! What the render loop sees happen between the worlds it draws: grasps, releases and blocks
//! changing mode (the overlay's latest event; the hand's events mark the action in time).

use common::{BlockMode, WorldView};

/// Something the render loop saw happen, from the world samples it draws (the stepper's own
/// events do not reach the renderer: grasps and releases are the world's grasped block
/// changing, the rest a block's mode changing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Event {
    pub kind: EventKind,
    /// The block's scene index.
    pub block: u32,
    /// Session time, seconds (the world's steps over its rate).
    pub time_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    Grasp,
    Release,
    /// The block's mode became this (other than by a grasp or a release).
    Became(BlockMode),
}

impl Event {
    /// `grasp red 1.05 s`, `release red 1.94 s`, `red resting 2.80 s`.
    pub fn text(&self, names: &[String]) -> String {
        let name = names.get(self.block as usize).map_or("?", String::as_str);
        match self.kind {
            EventKind::Grasp => format!("grasp {name} {:.2} s", self.time_s),
            EventKind::Release => format!("release {name} {:.2} s", self.time_s),
            EventKind::Became(m) => format!("{name} {} {:.2} s", m.name(), self.time_s),
        }
    }
}

/// Finds events between the world samples drawn; allocates only when made.
#[derive(Debug, Default)]
pub struct EventTracker {
    modes: Vec<BlockMode>,
    grasped: i32,
    seen: bool,
    /// The latest event so far.
    pub latest: Option<Event>,
    /// Events of the hand so far: grasps, releases, blocks becoming pushed or carried (what
    /// the preview's cut in time looks for, with the blocks' motion).
    pub hand_events: u64,
}

impl EventTracker {
    pub fn new(blocks: usize) -> EventTracker {
        EventTracker {
            modes: vec![BlockMode::Resting; blocks],
            grasped: -1,
            seen: false,
            latest: None,
            hand_events: 0,
        }
    }

    /// Compares `world` with the one observed before it.
    pub fn observe(&mut self, world: WorldView<'_>, time_s: f64) {
        for (i, b) in world.blocks().iter().enumerate().take(self.modes.len()) {
            let m = drawn_mode(world, i, b.mode());
            let was = std::mem::replace(&mut self.modes[i], m);
            let by_grasp = [m, was].contains(&BlockMode::Grasped);
            if self.seen && m != was && !by_grasp {
                if matches!(m, BlockMode::Pushed | BlockMode::Carried) {
                    self.hand_events += 1;
                }
                self.latest = Some(Event {
                    kind: EventKind::Became(m),
                    block: i as u32,
                    time_s,
                });
            }
        }
        let g = world.grasped_block;
        if self.seen && g != self.grasped {
            let (kind, block) = if g >= 0 {
                (EventKind::Grasp, g)
            } else {
                (EventKind::Release, self.grasped)
            };
            self.hand_events += 1;
            self.latest = Some(Event {
                kind,
                block: block as u32,
                time_s,
            });
        }
        self.grasped = g;
        self.seen = true;
    }
}

/// A block's mode as drawn: the grasped block shows as grasped.
pub(super) fn drawn_mode(world: WorldView<'_>, i: usize, mode: BlockMode) -> BlockMode {
    if world.grasped_block == i as i32 {
        BlockMode::Grasped
    } else {
        mode
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_are_grasps_releases_and_mode_changes() {
        let mut w = common::WorldSample::with_blocks(2);
        let mut t = EventTracker::new(2);
        t.observe(w.view(), 0.0);
        assert_eq!(t.latest, None);
        // A block settling is an event, not the hand's.
        w.blocks[0].mode = BlockMode::Free as u32;
        t.observe(w.view(), 0.5);
        assert_eq!(t.hand_events, 0);
        w.header.grasped_block = 1;
        t.observe(w.view(), 1.0);
        assert_eq!(
            t.latest.map(|e| (e.kind, e.block)),
            Some((EventKind::Grasp, 1))
        );
        w.header.grasped_block = -1;
        w.blocks[1].mode = BlockMode::Free as u32;
        t.observe(w.view(), 2.0);
        assert_eq!(
            t.latest.map(|e| (e.kind, e.block)),
            Some((EventKind::Release, 1))
        );
        w.blocks[1].mode = BlockMode::Resting as u32;
        t.observe(w.view(), 2.5);
        let e = t.latest.unwrap();
        assert_eq!(e.kind, EventKind::Became(BlockMode::Resting));
        let names = vec!["red".to_string(), "blue".to_string()];
        assert_eq!(e.text(&names), "blue resting 2.50 s");
        w.blocks[0].mode = BlockMode::Pushed as u32;
        t.observe(w.view(), 3.0);
        // The grasp, the release and the push.
        assert_eq!(t.hand_events, 3);
    }
}
