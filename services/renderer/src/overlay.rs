//! Text burnt into the preview's frames (on the CPU, after they are scaled to their final
//! size, so that the text stays crisp): the session time, each block's name and mode, the
//! latest event.
//!
//! The glyphs are font8x8's public-domain 8 x 8 bitmaps (ASCII; anything else prints as `?`):
//! no system font, nothing to find at run time, and legible at the preview's 640 x 360.

use common::BlockMode;

use crate::draw_list::mode_color_srgb;

/// A glyph's size, pixels.
pub const GLYPH: u32 = 8;
/// Distance between two lines' tops, pixels.
pub const LINE: u32 = 10;
/// The box's inner margin, pixels.
const PAD: u32 = 4;
/// Blocks listed one by one; a scene with more lists those the hand or gravity is acting on
/// (not resting), up to this many, and counts the rest by mode.
pub const LISTED_BLOCKS: usize = 6;
/// Characters of a block's name shown (names may be 128 long).
const NAME_CHARS: usize = 14;
/// The text's default colour.
pub const WHITE: [u8; 3] = [240, 240, 240];

/// An RGB image to write on: tightly packed, `width` x `height`.
pub struct Canvas<'a> {
    pub rgb: &'a mut [u8],
    pub width: u32,
    pub height: u32,
}

impl Canvas<'_> {
    /// Darkens the rectangle to 35 % (the text's background: it reads over sky and floor).
    pub fn shade(&mut self, x: u32, y: u32, w: u32, h: u32) {
        for yy in y..(y + h).min(self.height) {
            for xx in x..(x + w).min(self.width) {
                let i = ((yy * self.width + xx) * 3) as usize;
                for c in &mut self.rgb[i..i + 3] {
                    *c = (u16::from(*c) * 35 / 100) as u8;
                }
            }
        }
    }

    /// Writes `text` with its top-left corner at `x, y` (clipped at the edges); returns the x
    /// after it.
    pub fn text(&mut self, x: u32, y: u32, text: &str, rgb: [u8; 3]) -> u32 {
        let mut x = x;
        for ch in text.chars() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                '?' as usize
            };
            let glyph = font8x8::legacy::BASIC_LEGACY[code];
            for (row, bits) in glyph.iter().enumerate() {
                let py = y + row as u32;
                if py >= self.height {
                    break;
                }
                for col in 0..GLYPH {
                    let px = x + col;
                    // Bit 0 is the leftmost pixel.
                    if px < self.width && bits & (1 << col) != 0 {
                        let i = ((py * self.width + px) * 3) as usize;
                        self.rgb[i..i + 3].copy_from_slice(&rgb);
                    }
                }
            }
            x += GLYPH;
        }
        x
    }
}

/// One line of the overlay: pieces of text, each in its colour.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Line {
    pub pieces: Vec<(String, [u8; 3])>,
}

impl Line {
    fn plain(text: String) -> Line {
        Line {
            pieces: vec![(text, WHITE)],
        }
    }

    fn chars(&self) -> usize {
        self.pieces.iter().map(|(t, _)| t.chars().count()).sum()
    }
}

/// A name shortened to what the overlay shows.
fn short(name: &str) -> String {
    if name.chars().count() <= NAME_CHARS {
        name.to_string()
    } else {
        let mut s: String = name.chars().take(NAME_CHARS - 1).collect();
        s.push('~');
        s
    }
}

/// The overlay's lines: the time, the blocks (name in the block's colour, mode in its
/// outline's colour: the legend of the outlines), the latest event.
pub fn lines(
    time_s: f64,
    names: &[String],
    colors: &[[u8; 3]],
    modes: &[BlockMode],
    event: Option<&str>,
) -> Vec<Line> {
    let mut out = vec![Line::plain(format!("t {time_s:6.2} s"))];
    let n = modes.len().min(names.len());
    let listed: Vec<usize> = if n <= LISTED_BLOCKS {
        (0..n).collect()
    } else {
        (0..n)
            .filter(|&i| modes[i] != BlockMode::Resting)
            .take(LISTED_BLOCKS - 1)
            .collect()
    };
    let width = listed
        .iter()
        .map(|&i| short(&names[i]).chars().count())
        .max()
        .unwrap_or(0);
    for &i in &listed {
        let color = colors.get(i).copied().unwrap_or(WHITE);
        out.push(Line {
            pieces: vec![
                (format!("{:<width$} ", short(&names[i])), color),
                (modes[i].name().to_string(), mode_color_srgb(modes[i])),
            ],
        });
    }
    if n > listed.len() {
        let mut counts = [0usize; BlockMode::ALL.len()];
        for m in &modes[..n] {
            counts[*m as usize] += 1;
        }
        let mut line = Line::plain(format!("{n} blocks:"));
        for m in BlockMode::ALL {
            if counts[m as usize] > 0 {
                line.pieces.push((
                    format!(" {} {}", counts[m as usize], m.name()),
                    mode_color_srgb(m),
                ));
            }
        }
        out.push(line);
    }
    if let Some(e) = event {
        out.push(Line::plain(e.to_string()));
    }
    out
}

/// Draws `lines` in a shaded box at the canvas's top-left corner; returns the box
/// `(x, y, w, h)`.
pub fn draw(canvas: &mut Canvas<'_>, lines: &[Line]) -> (u32, u32, u32, u32) {
    let chars = lines.iter().map(Line::chars).max().unwrap_or(0) as u32;
    let w = (chars * GLYPH + 2 * PAD).min(canvas.width);
    let h = (lines.len() as u32 * LINE + 2 * PAD - (LINE - GLYPH)).min(canvas.height);
    canvas.shade(0, 0, w, h);
    for (k, line) in lines.iter().enumerate() {
        let y = PAD + k as u32 * LINE;
        let mut x = PAD;
        for (text, rgb) in &line.pieces {
            x = canvas.text(x, y, text, *rgb);
        }
    }
    (0, 0, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_overlay_writes_inside_its_box_and_nowhere_else() {
        let (w, h) = (200u32, 100u32);
        let mut rgb = vec![128u8; (w * h * 3) as usize];
        let names = vec!["red".to_string()];
        let l = lines(
            2.31,
            &names,
            &[[220, 40, 30]],
            &[BlockMode::Grasped],
            Some("grasp red 1.05 s"),
        );
        assert_eq!(l.len(), 3);
        assert_eq!(l[1].pieces[0].0, "red ");
        assert_eq!(l[1].pieces[1].0, "grasped");
        let mut c = Canvas {
            rgb: &mut rgb,
            width: w,
            height: h,
        };
        let (bx, by, bw, bh) = draw(&mut c, &l);
        assert!(bw > 16 * GLYPH && bh >= 3 * GLYPH, "{bw} x {bh}");
        let px = |x: u32, y: u32| {
            let i = ((y * w + x) * 3) as usize;
            [rgb[i], rgb[i + 1], rgb[i + 2]]
        };
        // Text pixels (white, the block's colour) and shade inside; untouched outside.
        let mut white = 0;
        let mut red = 0;
        for y in by..by + bh {
            for x in bx..bx + bw {
                match px(x, y) {
                    WHITE => white += 1,
                    [220, 40, 30] => red += 1,
                    _ => {}
                }
            }
        }
        assert!(white > 50 && red > 10, "white {white}, red {red}");
        for y in 0..h {
            for x in 0..w {
                if x >= bx + bw || y >= by + bh {
                    assert_eq!(px(x, y), [128; 3], "{x} {y}");
                }
            }
        }
    }

    #[test]
    fn many_blocks_list_the_busy_ones_and_count_the_rest() {
        let names: Vec<String> = (0..100).map(|i| format!("cube_{i}")).collect();
        let mut modes = vec![BlockMode::Resting; 100];
        modes[7] = BlockMode::Pushed;
        let l = lines(0.5, &names, &[], &modes, None);
        assert_eq!(l.len(), 3, "{l:?}");
        assert_eq!(l[1].pieces[0].0.trim(), "cube_7");
        let summary: String = l[2].pieces.iter().map(|p| p.0.as_str()).collect();
        assert_eq!(summary, "100 blocks: 99 resting 1 pushed");
    }
}
