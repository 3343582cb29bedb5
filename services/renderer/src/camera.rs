//! Off-axis stereo: two eyes IPD apart, parallel view directions, asymmetric frusta that share
//! one screen rectangle.
//!
//! Why off-axis and not two rotated ("toed-in") cameras: toe-in puts the two image planes at an
//! angle, which adds vertical disparity at the image corners (eye strain) and makes disparity
//! depend on position in the image. With a shared screen plane at distance d, a point at depth z
//! has horizontal screen disparity `ipd * (1 - d / z)` (right image minus left): zero on the
//! screen, positive (uncrossed) behind it, negative (crossed) in front, and no vertical disparity
//! at all. The tests measure exactly that in rendered pixels.

use glam::{DMat4, DVec3, DVec4, Mat4};

use crate::settings::CameraSettings;

/// Which eye.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Eye {
    Left = 0,
    Right = 1,
}

impl Eye {
    pub const BOTH: [Eye; 2] = [Eye::Left, Eye::Right];

    /// The eye's offset along the viewer's right axis, in units of half the IPD.
    fn sign(self) -> f64 {
        match self {
            Eye::Left => -1.0,
            Eye::Right => 1.0,
        }
    }
}

/// The viewer's frame: position, and orthonormal right / up / forward axes (world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Viewer {
    pub centre: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub forward: DVec3,
}

impl Viewer {
    /// The viewer of `c`; `c` must have passed `RenderSettings::validate` (eye != target).
    pub fn new(c: &CameraSettings) -> Viewer {
        let centre = DVec3::from_array(c.eye);
        let forward = (DVec3::from_array(c.target) - centre).normalize_or(DVec3::NEG_Z);
        // World up is +y; looking straight down or up, take -z as "up" on the screen.
        let world_up = if forward.cross(DVec3::Y).length() < 1e-6 {
            DVec3::NEG_Z
        } else {
            DVec3::Y
        };
        let right = forward.cross(world_up).normalize();
        let up = right.cross(forward);
        Viewer {
            centre,
            right,
            up,
            forward,
        }
    }

    /// Depth of a world point along the view direction (metres in front of the eyes' plane).
    pub fn depth(&self, p: DVec3) -> f64 {
        (p - self.centre).dot(self.forward)
    }
}

/// One eye's matrices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EyeView {
    pub position: DVec3,
    pub view: DMat4,
    pub projection: DMat4,
}

impl EyeView {
    /// World to clip space, f32 for the GPU.
    pub fn view_projection(&self) -> Mat4 {
        (self.projection * self.view).as_mat4()
    }

    /// Where a world point lands in this eye's image, in pixels from the top-left corner of the
    /// eye's own image (None behind the eye).
    pub fn project_px(&self, p: DVec3, width: u32, height: u32) -> Option<(f64, f64)> {
        let c = self.projection * self.view * DVec4::new(p.x, p.y, p.z, 1.0);
        if c.w <= 0.0 {
            return None;
        }
        let (x, y) = (c.x / c.w, c.y / c.w);
        Some((
            (x + 1.0) * 0.5 * width as f64,
            (1.0 - y) * 0.5 * height as f64,
        ))
    }
}

/// Both eyes for the camera `c` and an image of `width` x `height` pixels per eye.
pub fn stereo(c: &CameraSettings, width: u32, height: u32) -> [EyeView; 2] {
    let v = Viewer::new(c);
    let half_w = c.screen_width_m * 0.5;
    let half_h = half_w * height as f64 / width as f64;
    Eye::BOTH.map(|eye| {
        let eye_x = eye.sign() * c.ipd_m * 0.5;
        let position = v.centre + v.right * eye_x;
        // Parallel view directions: both eyes look along `forward`.
        let view = look_to(position, &v);
        // The shared screen rectangle, seen from this eye, scaled onto the near plane.
        let k = c.near_m / c.screen_distance_m;
        let projection = off_axis(
            (-half_w - eye_x) * k,
            (half_w - eye_x) * k,
            -half_h * k,
            half_h * k,
            c.near_m,
            c.far_m,
        );
        EyeView {
            position,
            view,
            projection,
        }
    })
}

/// World to view space for an eye at `p` with the viewer's axes (right-handed, looking down
/// -z, as `off_axis` expects).
fn look_to(p: DVec3, v: &Viewer) -> DMat4 {
    let (r, u, f) = (v.right, v.up, v.forward);
    DMat4::from_cols(
        DVec4::new(r.x, u.x, -f.x, 0.0),
        DVec4::new(r.y, u.y, -f.y, 0.0),
        DVec4::new(r.z, u.z, -f.z, 0.0),
        DVec4::new(-r.dot(p), -u.dot(p), f.dot(p), 1.0),
    )
}

/// The asymmetric perspective frustum (right-handed view space looking down -z, depth 0..1 as
/// wgpu wants): `l, r, b, t` are the near plane's bounds.
pub fn off_axis(l: f64, r: f64, b: f64, t: f64, n: f64, f: f64) -> DMat4 {
    DMat4::from_cols(
        DVec4::new(2.0 * n / (r - l), 0.0, 0.0, 0.0),
        DVec4::new(0.0, 2.0 * n / (t - b), 0.0, 0.0),
        DVec4::new((r + l) / (r - l), (t + b) / (t - b), f / (n - f), -1.0),
        DVec4::new(0.0, 0.0, n * f / (n - f), 0.0),
    )
}

/// The screen disparity, in pixels of one eye's image, of a point at `depth` metres: right
/// image x minus left image x. The formula the renderer must reproduce.
pub fn expected_disparity_px(c: &CameraSettings, width: u32, depth: f64) -> f64 {
    c.ipd_m * (1.0 - c.screen_distance_m / depth) * width as f64 / c.screen_width_m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> CameraSettings {
        CameraSettings {
            eye: [0.0, 0.1, 1.0],
            target: [0.0, 0.1, 0.0],
            ..CameraSettings::default()
        }
    }

    #[test]
    fn points_on_the_screen_plane_have_zero_disparity_and_no_vertical_disparity() {
        let c = cam();
        let [l, r] = stereo(&c, 320, 240);
        let p = DVec3::new(0.05, 0.13, 1.0 - c.screen_distance_m);
        let (lx, ly) = l.project_px(p, 320, 240).unwrap();
        let (rx, ry) = r.project_px(p, 320, 240).unwrap();
        assert!((lx - rx).abs() < 1e-9, "{lx} {rx}");
        assert!((ly - ry).abs() < 1e-9);
    }

    #[test]
    fn disparity_follows_ipd_times_one_minus_d_over_z() {
        let c = cam();
        let [l, r] = stereo(&c, 320, 240);
        for depth in [0.3, 0.5, 0.9, 1.5, 4.0] {
            let p = DVec3::new(-0.03, 0.02, 1.0 - depth);
            let (lx, ly) = l.project_px(p, 320, 240).unwrap();
            let (rx, ry) = r.project_px(p, 320, 240).unwrap();
            let want = expected_disparity_px(&c, 320, depth);
            assert!(
                (rx - lx - want).abs() < 1e-6,
                "depth {depth}: {} vs {want}",
                rx - lx
            );
            assert!((ly - ry).abs() < 1e-9);
        }
        // Behind the screen: uncrossed (positive); in front: crossed (negative).
        assert!(expected_disparity_px(&c, 320, 1.2) > 0.0);
        assert!(expected_disparity_px(&c, 320, 0.4) < 0.0);
    }

    #[test]
    fn the_screen_edges_map_to_the_image_edges_for_each_eye() {
        let c = cam();
        let [l, _] = stereo(&c, 320, 240);
        let v = Viewer::new(&c);
        // The screen's left edge, seen from the left eye, is the image's left edge.
        let edge = v.centre + v.forward * c.screen_distance_m - v.right * (c.screen_width_m / 2.0);
        let (x, _) = l.project_px(edge, 320, 240).unwrap();
        assert!(x.abs() < 1e-6, "{x}");
    }

    #[test]
    fn looking_straight_down_still_has_a_frame() {
        let c = CameraSettings {
            eye: [0.0, 1.0, 0.0],
            target: [0.0, 0.0, 0.0],
            ..CameraSettings::default()
        };
        let v = Viewer::new(&c);
        assert!(v.right.is_finite() && (v.right.length() - 1.0).abs() < 1e-9);
        assert!(v.depth(DVec3::ZERO) > 0.99);
    }
}
