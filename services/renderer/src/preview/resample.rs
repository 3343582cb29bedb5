//! Resampling the eye's pixels: shrinking a drawn frame by a whole factor as it is stored,
//! and scaling the crop of a stored frame to the preview's size.

use super::framing::Rect;
use crate::image::{Image, GAP_RGB};

/// `frame` (RGBA) shrunk by the whole factor `k` (box filter), as RGB.
pub(super) fn shrink_rgba(frame: &Image, k: u32) -> Vec<u8> {
    let (ow, oh) = (frame.width / k, frame.height / k);
    let mut out = Vec::with_capacity((ow * oh * 3) as usize);
    let n = k * k;
    for y in 0..oh {
        for x in 0..ow {
            let mut sum = [0u32; 3];
            for dy in 0..k {
                let row = ((y * k + dy) * frame.width) as usize;
                for dx in 0..k {
                    let i = (row + (x * k + dx) as usize) * 4;
                    for (c, s) in sum.iter_mut().enumerate() {
                        *s += u32::from(frame.rgba[i + c]);
                    }
                }
            }
            out.extend(sum.map(|s| (s / n) as u8));
        }
    }
    out
}

/// One bilinear tap along an axis: the two source pixels and the second one's weight; None
/// outside the image.
type Tap = Option<(u32, u32, f32)>;

/// The taps of `n` output pixels along an axis of `size` source pixels, `taps` per output
/// pixel, for the source span `from .. from + n * step`.
fn axis_taps(from: f64, step: f64, n: u32, taps: u32, size: u32, out: &mut Vec<Tap>) {
    out.clear();
    for o in 0..n {
        for t in 0..taps {
            let x = from + (f64::from(o) + (f64::from(t) + 0.5) / f64::from(taps)) * step;
            if x < 0.0 || x > f64::from(size) {
                out.push(None);
                continue;
            }
            // Pixel centres at half integers.
            let f = (x - 0.5).clamp(0.0, f64::from(size - 1));
            let a = f.floor() as u32;
            let b = (a + 1).min(size - 1);
            out.push(Some((a, b, (f - f64::from(a)) as f32)));
        }
    }
}

/// `crop` of the RGB image `src` (`sw` x `sh`) scaled into `out` (`ow` x `oh`): bilinear,
/// with as many taps per pixel as it shrinks; outside the image, the gap colour. The taps are
/// worked out once per column and row, not per pixel.
pub(super) fn resample(
    src: &[u8],
    sw: u32,
    sh: u32,
    crop: &Rect,
    out: &mut [u8],
    ow: u32,
    oh: u32,
) {
    if sw == 0 || sh == 0 {
        return;
    }
    let sx = crop.width() / f64::from(ow);
    let sy = crop.height() / f64::from(oh);
    let (tx, ty) = (sx.ceil().max(1.0) as u32, sy.ceil().max(1.0) as u32);
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    axis_taps(crop.x0, sx, ow, tx, sw, &mut xs);
    axis_taps(crop.y0, sy, oh, ty, sh, &mut ys);
    let norm = 1.0 / (tx * ty) as f32;
    let gap = GAP_RGB.map(f32::from);
    let px = |x: u32, y: u32| {
        let i = ((y * sw + x) * 3) as usize;
        [
            f32::from(src[i]),
            f32::from(src[i + 1]),
            f32::from(src[i + 2]),
        ]
    };
    for y in 0..oh as usize {
        for x in 0..ow as usize {
            let mut sum = [0.0f32; 3];
            for yt in &ys[y * ty as usize..(y + 1) * ty as usize] {
                for xt in &xs[x * tx as usize..(x + 1) * tx as usize] {
                    let v = match (yt, xt) {
                        (Some((y0, y1, ay)), Some((x0, x1, ax))) => {
                            let (p00, p10) = (px(*x0, *y0), px(*x1, *y0));
                            let (p01, p11) = (px(*x0, *y1), px(*x1, *y1));
                            std::array::from_fn(|c| {
                                let top = p00[c] + (p10[c] - p00[c]) * ax;
                                let bottom = p01[c] + (p11[c] - p01[c]) * ax;
                                top + (bottom - top) * ay
                            })
                        }
                        _ => gap,
                    };
                    for c in 0..3 {
                        sum[c] += v[c];
                    }
                }
            }
            let o = (y * ow as usize + x) * 3;
            for c in 0..3 {
                out[o + c] = (sum[c] * norm).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}
