//! A block's own colour (sRGB, 0 to 1), one rule for every view of a scene: the renderer's
//! frames and preview, and the Foxglove scene (`scene-view`) of the live view and recordings.
//! A block keeps its colour whatever its mode; each view shows the mode another way (the
//! renderer by the block's outline, Foxglove by its label).

/// Colours a block named after one takes (sRGB, 0 to 1): its name's first word, in lower case
/// (`red`, `red_0_0_0`, `Red-cube`).
pub const NAMED_COLORS: [(&str, [f32; 3]); 15] = [
    ("red", [0.85, 0.15, 0.12]),
    ("green", [0.20, 0.70, 0.25]),
    ("blue", [0.20, 0.40, 0.90]),
    ("yellow", [0.95, 0.82, 0.15]),
    ("orange", [0.98, 0.55, 0.10]),
    ("purple", [0.55, 0.25, 0.75]),
    ("violet", [0.55, 0.25, 0.75]),
    ("cyan", [0.15, 0.75, 0.85]),
    ("magenta", [0.85, 0.20, 0.70]),
    ("pink", [0.95, 0.55, 0.70]),
    ("brown", [0.55, 0.35, 0.20]),
    ("white", [0.92, 0.92, 0.92]),
    ("black", [0.12, 0.12, 0.12]),
    ("grey", [0.50, 0.50, 0.50]),
    ("gray", [0.50, 0.50, 0.50]),
];

/// Colours for blocks whose name is no colour word and whose table gives none, by scene
/// index (sRGB): distinct hues, none close to the floor's grey or the hand's skin.
pub const PALETTE: [[f32; 3]; 8] = [
    [0.85, 0.15, 0.12],
    [0.20, 0.40, 0.90],
    [0.20, 0.70, 0.25],
    [0.95, 0.82, 0.15],
    [0.55, 0.25, 0.75],
    [0.15, 0.75, 0.85],
    [0.98, 0.55, 0.10],
    [0.85, 0.20, 0.70],
];

/// The colour a name stands for: its first word (up to `_`, `-`, a space or a digit), when
/// that is a colour word.
pub fn color_for_name(name: &str) -> Option<[f32; 3]> {
    let word = name
        .split(|c: char| c == '_' || c == '-' || c == ' ' || c.is_ascii_digit())
        .next()?
        .to_ascii_lowercase();
    NAMED_COLORS
        .iter()
        .find(|(n, _)| *n == word)
        .map(|(_, rgb)| *rgb)
}

/// Each block's own colour (sRGB, 0 to 1), in scene order: the scene's `color` when its table
/// has one, else the colour its name says, else the palette's, one colour per table: the
/// copies of a lattice (`cube_3_0_7`, see the scene loader) share their table's, so that a
/// field reads as one thing and a block the hand moves stands out by its outline.
pub fn block_colors(scene: &crate::config::Scene) -> Vec<[f32; 3]> {
    let mut tables: Vec<&str> = Vec::new();
    scene
        .blocks
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let table = lattice_table(&b.name);
            let k = tables.iter().position(|t| *t == table).unwrap_or_else(|| {
                tables.push(table);
                tables.len() - 1
            });
            scene
                .world
                .block_colors
                .get(i)
                .copied()
                .flatten()
                .or_else(|| color_for_name(&b.name))
                .unwrap_or(PALETTE[k % PALETTE.len()])
        })
        .collect()
}

/// A lattice copy's table name (`cube` of `cube_3_0_7`); any other name is its own.
fn lattice_table(name: &str) -> &str {
    let mut rest = name;
    for _ in 0..3 {
        match rest.rsplit_once('_') {
            Some((head, n)) if !n.is_empty() && n.bytes().all(|c| c.is_ascii_digit()) => {
                rest = head
            }
            _ => return name,
        }
    }
    rest
}
