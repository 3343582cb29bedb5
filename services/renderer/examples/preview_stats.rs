//! Measures a preview GIF from its pixels alone, so that any preview (this version's or an
//! older one's) is measured the same way:
//!
//! `cargo run -p renderer --release --example preview_stats -- PREVIEW.gif [--sheet OUT.png N]
//! [--frame K OUT.png]`
//!
//! Per frame it sorts the pixels (the overlay's top-left box, [`OVERLAY_W`] x [`OVERLAY_H`],
//! left out) into sky (the background's blue-grey), floor (neutral grey: the floor, its grid and
//! shadows), hand (the skin colour) and the rest (blocks and their outlines), and prints:
//! - **loop**: the frames, the loop's length and how much of it is still (a frame that differs
//!   from the next in fewer than 0.2 % of its pixels: nothing moves on screen);
//! - **hand**: the frames where the hand shows, and of those where it touches the picture's
//!   edge (cut by it);
//! - **floor**: the mean fraction of the picture that is floor, and that the hand and the
//!   blocks cover;
//! - **blocks**: the median over frames of the blocks' size, the square root of their pixels
//!   (one block: its side in pixels, about).
//!
//! `--sheet OUT.png N` also writes N frames evenly spread over the loop, side by side at half
//! size, as a PNG (the before/after strips in docs/renderer.md); `--frame K OUT.png` frame K.

use std::io::BufWriter;
use std::path::Path;

/// The overlay's box, left out of the measures (3 lines of text: time, block, event).
const OVERLAY_W: usize = 200;
const OVERLAY_H: usize = 42;

struct Frame {
    rgba: Vec<u8>,
    delay_ms: u32,
}

fn decode(path: &Path) -> Result<(usize, usize, Vec<Frame>), Box<dyn std::error::Error>> {
    let file = std::fs::File::open(path)?;
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut dec = opts.read_info(std::io::BufReader::new(file))?;
    let (w, h) = (usize::from(dec.width()), usize::from(dec.height()));
    let mut canvas = vec![0u8; w * h * 4];
    let mut frames = Vec::new();
    while let Some(f) = dec.read_next_frame()? {
        let (fl, ft) = (usize::from(f.left), usize::from(f.top));
        let fw = usize::from(f.width);
        for (k, px) in f.buffer.chunks_exact(4).enumerate() {
            let (x, y) = (fl + k % fw, ft + k / fw);
            if x < w && y < h && px[3] > 0 {
                let i = (y * w + x) * 4;
                canvas[i..i + 4].copy_from_slice(px);
            }
        }
        frames.push(Frame {
            rgba: canvas.clone(),
            delay_ms: u32::from(f.delay) * 10,
        });
    }
    Ok((w, h, frames))
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Class {
    Sky,
    Floor,
    Hand,
    Other,
}

fn classify(p: &[u8]) -> Class {
    let (r, g, b) = (i32::from(p[0]), i32::from(p[1]), i32::from(p[2]));
    if b > r + 12 && b >= g {
        return Class::Sky;
    }
    let (hi, lo) = (r.max(g).max(b), r.min(g).min(b));
    if hi - lo <= 14 {
        return Class::Floor;
    }
    // Skin: red over green over blue, warm but not saturated (an orange or red block is).
    if r > g && g > b && r > 60 && (r - b) * 100 <= 55 * r && (g - b) * 100 >= 8 * r {
        return Class::Hand;
    }
    Class::Other
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(input) = args.first() else {
        return Err("usage: preview_stats PREVIEW.gif [--sheet OUT.png N]".into());
    };
    let (w, h, frames) = decode(Path::new(input))?;
    if frames.is_empty() {
        return Err(format!("{input}: no frames").into());
    }
    let measured = |x: usize, y: usize| !(x < OVERLAY_W && y < OVERLAY_H);
    let total: usize = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| measured(x, y))
        .count();
    let (mut hand_frames, mut hand_cut, mut floor_sum, mut cover_sum) = (0, 0, 0.0, 0.0);
    let mut block_sizes = Vec::new();
    let mut still_ms = 0;
    let loop_ms: u32 = frames.iter().map(|f| f.delay_ms).sum();
    for (k, f) in frames.iter().enumerate() {
        let (mut hand, mut floor, mut other, mut edge) = (0usize, 0usize, 0usize, false);
        for y in 0..h {
            for x in 0..w {
                if !measured(x, y) {
                    continue;
                }
                let i = (y * w + x) * 4;
                match classify(&f.rgba[i..i + 3]) {
                    Class::Hand => {
                        hand += 1;
                        edge |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
                    }
                    Class::Floor => floor += 1,
                    Class::Other => other += 1,
                    Class::Sky => {}
                }
            }
        }
        // A few stray pixels (anti-aliased edges) are no hand.
        if hand >= 30 {
            hand_frames += 1;
            hand_cut += usize::from(edge);
        }
        floor_sum += floor as f64 / total as f64;
        cover_sum += (hand + other) as f64 / total as f64;
        block_sizes.push((other as f64).sqrt());
        let next = &frames[(k + 1) % frames.len()];
        let changed = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| measured(x, y))
            .filter(|&(x, y)| {
                let i = (y * w + x) * 4;
                (0..3).any(|c| f.rgba[i + c].abs_diff(next.rgba[i + c]) > 24)
            })
            .count();
        if changed * 500 < total {
            still_ms += f.delay_ms;
        }
        println!(
            "frame {k:3}: {:4} ms, hand {hand:6} px{}, floor {:4.1} %, blocks {:5.1} px, changed {:4.1} %",
            f.delay_ms,
            if edge { " (cut)" } else { "" },
            100.0 * floor as f64 / total as f64,
            (other as f64).sqrt(),
            100.0 * changed as f64 / total as f64,
        );
    }
    block_sizes.sort_by(f64::total_cmp);
    let n = frames.len();
    println!("{input}: {w} x {h}");
    println!(
        "loop: {n} frames, {:.2} s, still {:.2} s ({:.0} %)",
        f64::from(loop_ms) / 1000.0,
        f64::from(still_ms) / 1000.0,
        100.0 * f64::from(still_ms) / f64::from(loop_ms.max(1))
    );
    println!(
        "hand: shown in {hand_frames} of {n} frames, cut by the edge in {hand_cut}, in whole in {} of {n}",
        hand_frames - hand_cut
    );
    println!(
        "floor: {:.0} % of the picture; the hand and the blocks: {:.1} %",
        100.0 * floor_sum / n as f64,
        100.0 * cover_sum / n as f64
    );
    println!("blocks: {:.0} px (median over frames)", block_sizes[n / 2]);
    if let Some(i) = args.iter().position(|a| a == "--frame") {
        let k: usize = args.get(i + 1).ok_or("--frame K OUT.png")?.parse()?;
        let out = args.get(i + 2).ok_or("--frame K OUT.png")?;
        let f = frames.get(k).ok_or(format!("no frame {k}"))?;
        let rgb: Vec<u8> = f
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        write_rgb(Path::new(out), w, h, &rgb)?;
    }
    if let Some(i) = args.iter().position(|a| a == "--sheet") {
        let out = args.get(i + 1).ok_or("--sheet OUT.png N")?;
        let count: usize = args.get(i + 2).map_or(Ok(6), |s| s.parse())?;
        write_sheet(Path::new(out), w, h, &frames, count.clamp(1, n))?;
    }
    Ok(())
}

/// `count` frames evenly spread over the loop, side by side at half size, with a 4 px gap.
fn write_sheet(
    out: &Path,
    w: usize,
    h: usize,
    frames: &[Frame],
    count: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let (hw, hh, gap) = (w / 2, h / 2, 4);
    let sw = count * hw + (count - 1) * gap;
    let mut rgb = vec![255u8; sw * hh * 3];
    for j in 0..count {
        let f = &frames[j * frames.len() / count];
        for y in 0..hh {
            for x in 0..hw {
                for c in 0..3 {
                    let s: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .iter()
                        .map(|(dx, dy)| u32::from(f.rgba[((2 * y + dy) * w + 2 * x + dx) * 4 + c]))
                        .sum();
                    rgb[(y * sw + j * (hw + gap) + x) * 3 + c] = (s / 4) as u8;
                }
            }
        }
    }
    write_rgb(out, sw, hh, &rgb)
}

/// An RGB image as a PNG file.
fn write_rgb(out: &Path, w: usize, h: usize, rgb: &[u8]) -> Result<(), Box<dyn std::error::Error>> {
    let file = std::fs::File::create(out)?;
    let mut enc = png::Encoder::new(BufWriter::new(file), w as u32, h as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::High);
    enc.write_header()?.write_image_data(rgb)?;
    Ok(())
}
