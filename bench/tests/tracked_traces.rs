//! docs/model.md "Tracked hands" on real recordings (issue 41): every hand of the CARL
//! recordings in ../shared/data/carl that closes on something, a cube placed where it closes
//! (`handblocks_bench::hands::traces`), under the paper's rules and the tracked ones. The
//! tracked rules never flicker (a release followed by a grasp of the same block within 200 ms)
//! and never drop more than the paper's rules.

use std::collections::BTreeMap;
use std::path::Path;

#[test]
fn tracked_hands_never_flicker_on_the_real_recordings_and_drop_no_more_than_the_paper() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/carl");
    if !dir.is_dir() {
        eprintln!("skipped: {} is missing", dir.display());
        return;
    }
    let rows = handblocks_bench::hands::traces::measure(&dir, &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"));
    let mut by_hand: BTreeMap<(String, String), BTreeMap<String, (u32, u32)>> = BTreeMap::new();
    for r in &rows {
        by_hand
            .entry((r.file.clone(), r.hand.clone()))
            .or_default()
            .insert(r.rules.clone(), (r.flickers, r.drops));
    }
    assert!(by_hand.len() >= 4, "closing hands found: {by_hand:?}");
    for ((file, hand), rules) in &by_hand {
        let (Some(&(flickers, drops)), Some(&(_, paper_drops))) =
            (rules.get("tracked"), rules.get("paper"))
        else {
            panic!("{file} {hand}: both rule sets measured: {rules:?}");
        };
        assert_eq!(flickers, 0, "{file} {hand}: tracked flickers");
        assert!(
            drops <= paper_drops,
            "{file} {hand}: {drops} > {paper_drops}"
        );
    }
}
