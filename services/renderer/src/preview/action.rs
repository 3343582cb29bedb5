//! Finding the action in time: the moments a block moves or is in the hand (a grasp, a
//! release, a push), the stretch of kept worlds shown around them, the blocks framed, and the
//! frames picked from that stretch with how long each shows (steps 1-4 of the plan; the
//! cameras are [`super::framing`]'s).

use common::BlockMode;
use glam::DVec3;

use super::store::KeptState;
use super::{KEEP_HZ, LEAD_S, MAX_FRAMES, MAX_LEAD_S, TAIL_S};

/// The shortest stretch shown, seconds (a lone event gets this much around it).
const MIN_WINDOW_S: f64 = 1.0;
/// A block that moved at least this far between two kept worlds moved (metres).
const MOTION_M: f64 = 0.002;
/// The hand closes in on a block within this distance of its bounding sphere (metres).
const NEAR_M: f64 = 0.2;
/// The hand touches a block within this distance of its bounding sphere (metres).
const TOUCH_M: f64 = 0.02;
/// Worlds within this time of a moment of action are all shown; the rest, calm, one in
/// `1 / CALM_WEIGHT`.
const BUSY_S: f64 = 0.3;
const CALM_WEIGHT: f64 = 1.0 / 3.0;
/// A frame is shown at most this long (a calm stretch's sparse frames play faster).
const MAX_DELAY_S: f64 = 0.15;
/// A hand shows when one of its points is this far above the floor (metres); a lead or a
/// tail where it does not is cut to this long (seconds).
const SHOWS_ABOVE_M: f64 = 0.01;
const HIDDEN_S: f64 = 0.2;

/// A block is in the hand in these modes (the world says so as it happens).
fn in_hand(m: BlockMode) -> bool {
    matches!(
        m,
        BlockMode::Grasped | BlockMode::Carried | BlockMode::Pushed
    )
}

/// Block `k`'s centre in `s`.
pub(super) fn centre_of(s: &KeptState, k: usize) -> DVec3 {
    DVec3::from_array(s.blocks[k].pose.position)
}

/// Whether block `k` moved more than [`MOTION_M`] from `a` to `b`.
fn block_moved(a: &KeptState, b: &KeptState, k: usize) -> bool {
    centre_of(a, k).distance(centre_of(b, k)) > MOTION_M
}

/// Block `k`'s radius (its bounding sphere's, metres), a default where the scene gave none.
pub(super) fn radius_of(radii: &[f64], k: usize) -> f64 {
    radii.get(k).copied().unwrap_or(0.05)
}

/// What the preview shows of the kept worlds, in time: the plan's steps 1-4.
pub(super) struct Shown {
    /// Session time of the first and the last world kept, seconds.
    pub(super) session_s: (f64, f64),
    /// The first and the last moment of action, seconds; None when nothing happened.
    pub(super) action_s: Option<(f64, f64)>,
    /// The blocks every kept world holds (the fewest any holds).
    pub(super) blocks: usize,
    /// Whether each block is framed: it moved or was in the hand, or the hand touches it in
    /// the stretch shown (every block when there are none).
    pub(super) framed: Vec<bool>,
    /// The kept worlds shown (indices), each one's time and delay (milliseconds).
    pub(super) chosen: Vec<usize>,
    pub(super) times: Vec<f64>,
    pub(super) delays: Vec<u32>,
}

/// The frames a preview of `states` shows, and for how long; None when no world was kept.
/// See the module's comment.
pub(super) fn shown(states: &[KeptState], radii: &[f64]) -> Option<Shown> {
    let n = states.len();
    let session_s = (states.first()?.facts.time_s, states.last()?.facts.time_s);
    let t = |i: usize| states[i].facts.time_s;
    let blocks = states.iter().map(|s| s.blocks.len()).min().unwrap_or(0);
    let radius = |k: usize| radius_of(radii, k);

    // 1. The moments of action, and the blocks that moved or were in the hand.
    let mut moved = vec![false; blocks];
    let mut action = vec![false; n];
    for i in 0..n {
        let s = &states[i];
        for (k, m) in moved.iter_mut().enumerate() {
            let held = s.facts.modes.get(k).is_some_and(|m| in_hand(*m));
            if held || (i > 0 && block_moved(&states[i - 1], s, k)) {
                *m = true;
                action[i] = true;
            }
        }
        action[i] |= i > 0 && s.hand_events != states[i - 1].hand_events;
    }
    let busy: Vec<usize> = (0..n).filter(|&i| action[i]).collect();
    let action_s = busy.first().zip(busy.last()).map(|(&a, &b)| (t(a), t(b)));

    // 2. The stretch shown: from LEAD_S before the first moment (earlier while the hand closes
    //    in on a block that moves, up to MAX_LEAD_S) to TAIL_S after the last.
    let near = |s: &KeptState, k: usize, p: DVec3, within: f64| {
        centre_of(s, k).distance(p) < radius(k) + within
    };
    // A hand below the floor (a trace's resting hand) does not show: a lead or a tail of
    // that is cut to HIDDEN_S (in a session with a hand that shows at all).
    let shows = |s: &KeptState| s.hand_points().any(|p| p.y > SHOWS_ABOVE_M);
    let has_hand = states.iter().any(shows);
    let (lo, hi) = match (busy.first(), busy.last()) {
        (Some(&a), Some(&b)) => {
            let closing_in = |s: &KeptState| {
                s.hand_points()
                    .any(|p| (0..blocks).any(|k| moved[k] && near(s, k, p, NEAR_M)))
            };
            let hidden = |i: usize, from: f64| {
                has_hand && (t(i) - from).abs() > HIDDEN_S && !shows(&states[i])
            };
            let mut lo = a;
            while lo > 0
                && !hidden(lo - 1, t(a))
                && (t(lo - 1) >= t(a) - LEAD_S
                    || (t(lo - 1) >= t(a) - MAX_LEAD_S && closing_in(&states[lo - 1])))
            {
                lo -= 1;
            }
            let mut hi = b;
            while hi + 1 < n && !hidden(hi + 1, t(b)) && t(hi + 1) <= t(b) + TAIL_S + 1e-9 {
                hi += 1;
            }
            // A lone moment gets MIN_WINDOW_S around it.
            let short = MIN_WINDOW_S - (t(hi) - t(lo));
            if short > 0.0 {
                let (start, end) = (t(lo) - 0.5 * short, t(hi) + 0.5 * short);
                lo = (0..n).find(|&i| t(i) >= start - 1e-9).unwrap_or(0);
                hi = (0..n).rev().find(|&i| t(i) <= end + 1e-9).unwrap_or(n - 1);
            }
            (lo, hi.max(lo))
        }
        _ => (0, n - 1),
    };

    // 3. The blocks framed: those that moved or were in the hand, and those the hand touches
    //    in the stretch shown; every block when there are none.
    let mut framed = moved;
    for s in &states[lo..=hi] {
        for p in s.hand_points() {
            for (k, f) in framed.iter_mut().enumerate() {
                *f = *f || near(s, k, p, TOUCH_M);
            }
        }
    }
    if !framed.contains(&true) {
        framed.iter_mut().for_each(|f| *f = true);
    }

    // 4. The frames: every kept world near a moment of action, one in 1 / CALM_WEIGHT of the
    //    rest, all of it thinned evenly when that is more than MAX_FRAMES.
    let weight = |i: usize| {
        if busy.is_empty() || busy.iter().any(|&j| (t(i) - t(j)).abs() <= BUSY_S) {
            1.0
        } else {
            CALM_WEIGHT
        }
    };
    let total: f64 = (lo..=hi).map(weight).sum();
    let step = (total / MAX_FRAMES as f64).max(1.0);
    let mut chosen: Vec<usize> = Vec::new();
    let (mut acc, mut next) = (0.0, 0.0);
    for i in lo..=hi {
        if acc + 1e-9 >= next {
            chosen.push(i);
            next += step;
        }
        acc += weight(i);
    }
    if chosen.last() != Some(&hi) {
        chosen.push(hi);
    }
    if chosen.len() > MAX_FRAMES {
        let m = chosen.len();
        chosen = (0..MAX_FRAMES)
            .map(|k| chosen[k * (m - 1) / (MAX_FRAMES - 1)])
            .collect();
    }
    let m = chosen.len();
    let times: Vec<f64> = chosen.iter().map(|&i| t(i)).collect();
    // Each frame shows until the next one's time (the last one as long as a kept world),
    // from 20 ms to MAX_DELAY_S, averaged over its neighbours: the worlds kept are those
    // the render loop drew, at uneven times, and the motion should play evenly.
    let gaps: Vec<f64> = (0..m)
        .map(|k| {
            let gap = times.get(k + 1).map_or(1.0 / KEEP_HZ, |n| n - times[k]);
            gap.clamp(0.02, MAX_DELAY_S)
        })
        .collect();
    let delays: Vec<u32> = (0..m)
        .map(|k| {
            let around = &gaps[k.saturating_sub(2)..(k + 3).min(m)];
            let mean = around.iter().sum::<f64>() / around.len() as f64;
            (mean * 100.0).round() as u32 * 10
        })
        .collect();
    Some(Shown {
        session_s,
        action_s,
        blocks,
        framed,
        chosen,
        times,
        delays,
    })
}
