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

/// The stereo viewer: where the head is, where it looks, and the physical screen the images
/// are shown on. The screen is a window into the world at `screen_distance_m` in front of the
/// eyes: points at that distance have zero disparity, farther ones appear behind the screen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSettings {
    /// Midpoint between the eyes, world frame, metres.
    pub eye: [f64; 3],
    /// A point straight ahead of the viewer (both eyes look parallel, in this direction).
    pub target: [f64; 3],
    /// Interpupillary distance, metres (adult mean 63 mm; 50-75 mm covers most adults).
    pub ipd_m: f64,
    /// Eyes to screen, metres (the zero-disparity plane).
    pub screen_distance_m: f64,
    /// The screen's visible width for one eye's image, metres; the height follows from the
    /// image's aspect ratio (square pixels).
    pub screen_width_m: f64,
    pub near_m: f64,
    pub far_m: f64,
}

impl Default for CameraSettings {
    /// A seated user at a desk monitor (24", 0.6 m away), the virtual head 1.3 m from the
    /// origin and looking 32 degrees down at it: blocks within about 0.4 m of the origin and
    /// the hand 0.1-0.4 m above the floor are in view.
    fn default() -> Self {
        CameraSettings {
            eye: [0.0, 0.75, 1.1],
            target: [0.0, 0.05, 0.0],
            ipd_m: 0.063,
            screen_distance_m: 0.6,
            screen_width_m: 0.52,
            near_m: 0.02,
            far_m: 20.0,
        }
    }
}

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

/// A sphere the view must hold: a point of the scene and how far around it matters.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Interest {
    centre: DVec3,
    radius: f64,
}

/// Where a hand reaches around its wrist (fingers included), metres.
const HAND_REACH_M: f64 = 0.12;
/// Around blocks with no scripted hand (a replay or devices), the hand's likely reach.
const UNSCRIPTED_REACH_M: f64 = 0.3;
/// A hand moving at least this fast between two keys may throw what it holds.
const THROW_SPEED: f64 = 0.5;
/// The view's margin on each side, as a fraction of the half field.
const MARGIN: f64 = 0.06;

/// An eye point and target that frame `scene` for the camera `c` (its direction of view, the
/// default user's, above and in front of the scene at +z, is kept; its eye and target are
/// replaced): every block, the scripted hand's path within its reach, and the flight of what
/// the hand (or a block's own initial velocity) throws, up to its landing, fill the view with
/// a margin. Returns `(eye, target)`.
pub fn frame_scene(
    scene: &common::config::Scene,
    c: &CameraSettings,
    width: u32,
    height: u32,
) -> ([f64; 3], [f64; 3]) {
    let g = scene.world.gravity;
    let mut pts: Vec<Interest> = Vec::new();
    for b in &scene.blocks {
        let radius = block_radius(&b.shape);
        let p = DVec3::from_array(b.position);
        pts.push(Interest { centre: p, radius });
        let v = DVec3::from_array(b.velocity);
        if v.length() > 1e-9 {
            pts.extend(flight(p, v, g, radius));
        }
    }
    // A hand of one key rests (the hand a scene without [hand] gets, out of the way): the view
    // is of the blocks.
    match scene.hand.as_ref().filter(|h| h.keys.len() > 1) {
        Some(h) => {
            for k in &h.keys {
                pts.push(Interest {
                    centre: DVec3::from_array(k.wrist),
                    radius: HAND_REACH_M,
                });
            }
            // The fastest stretch between keys: what it holds may fly on from there.
            let fastest = h
                .keys
                .windows(2)
                .filter(|w| w[1].t > w[0].t)
                .map(|w| {
                    let v = (DVec3::from_array(w[1].wrist) - DVec3::from_array(w[0].wrist))
                        / (w[1].t - w[0].t);
                    (v, DVec3::from_array(w[1].wrist))
                })
                .max_by(|a, b| a.0.length().total_cmp(&b.0.length()));
            if let Some((v, p)) = fastest.filter(|(v, _)| v.length() >= THROW_SPEED) {
                pts.extend(flight(p, v, g, 0.05));
            }
        }
        None => {
            for b in &scene.blocks {
                pts.push(Interest {
                    centre: DVec3::from_array(b.position),
                    radius: UNSCRIPTED_REACH_M,
                });
            }
        }
    }
    if pts.is_empty() {
        return (c.eye, c.target);
    }
    // The user's side of the scene (+z), from above: of these directions of view, the one
    // that frames it largest.
    let tan_h = c.screen_width_m * 0.5 / c.screen_distance_m;
    let tan_v = tan_h * height as f64 / width.max(1) as f64;
    let mut best: Option<(f64, DVec3, DVec3)> = None;
    for elevation in [18.0f64, 25.0, 32.0] {
        for azimuth in [0.0f64, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0] {
            let (el, az) = (elevation.to_radians(), azimuth.to_radians());
            let forward = DVec3::new(-az.sin() * el.cos(), -el.sin(), -az.cos() * el.cos());
            let (d, target) = fit(&pts, forward, tan_h, tan_v);
            // Prefer the straight view unless another frames it clearly larger.
            if best.is_none_or(|(b, _, _)| d < 0.93 * b) {
                best = Some((d, target, forward));
            }
        }
    }
    let Some((d, target, forward)) = best else {
        return (c.eye, c.target);
    };
    let eye = target - forward * d;
    (eye.to_array(), target.to_array())
}

/// A mono camera (no IPD) that frames these spheres (centre, radius) in a `width` x `height`
/// view with the margin: what the preview uses to frame the action a whole session showed.
/// It looks the way `c` looks unless one of a few other directions from the user's side
/// (10-60 degrees down, up to 60 degrees to either side) frames them clearly larger (a flat,
/// wide field is better seen from higher up). None when there is no finite sphere.
pub fn frame_spheres(
    spheres: &[(DVec3, f64)],
    c: &CameraSettings,
    width: u32,
    height: u32,
) -> Option<CameraSettings> {
    let pts: Vec<Interest> = interests(spheres).collect();
    if pts.is_empty() {
        return None;
    }
    let tan_h = c.screen_width_m * 0.5 / c.screen_distance_m;
    let tan_v = tan_h * height as f64 / width.max(1) as f64;
    let own = Viewer::new(c).forward;
    let (d_own, t_own) = fit(&pts, own, tan_h, tan_v);
    let mut best = (d_own, t_own, own);
    for elevation in [10.0f64, 18.0, 25.0, 32.0, 40.0, 50.0, 60.0] {
        for azimuth in [0.0f64, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0] {
            let (el, az) = (elevation.to_radians(), azimuth.to_radians());
            let forward = DVec3::new(-az.sin() * el.cos(), -el.sin(), -az.cos() * el.cos());
            let (d, target) = fit(&pts, forward, tan_h, tan_v);
            // The session's own direction unless another is clearly closer.
            if d < 0.85 * d_own && d < best.0 {
                best = (d, target, forward);
            }
        }
    }
    let (d, target, forward) = best;
    Some(CameraSettings {
        eye: (target - forward * d).to_array(),
        target: target.to_array(),
        ipd_m: 0.0,
        ..*c
    })
}

/// For a direction of view: the nearest eye distance at which every sphere is inside both
/// fields with the margin, and the target it looks at.
fn fit(pts: &[Interest], forward: DVec3, tan_h: f64, tan_v: f64) -> (f64, DVec3) {
    let axes = axes_of(forward);
    let target = centre(pts, &axes);
    (
        distance(pts.iter().copied(), target, &axes, (tan_h, tan_v), 0.3),
        target,
    )
}

/// The viewer's axes for a direction of view (from the origin).
fn axes_of(forward: DVec3) -> Viewer {
    Viewer::new(&CameraSettings {
        eye: [0.0, 0.0, 0.0],
        target: forward.to_array(),
        ..CameraSettings::default()
    })
}

/// The point to look at so that the spheres' extent across the view (along right and up) is
/// centred in it.
fn centre(pts: &[Interest], axes: &Viewer) -> DVec3 {
    let (lo, hi) = pts.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| {
            (
                lo.min(p.centre - DVec3::splat(p.radius)),
                hi.max(p.centre + DVec3::splat(p.radius)),
            )
        },
    );
    // Centre the view on the middle of the spheres' extents along right and up.
    let mid = (lo + hi) * 0.5;
    let (mut r_lo, mut r_hi, mut u_lo, mut u_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in pts {
        let q = p.centre - mid;
        let (r, u) = (q.dot(axes.right), q.dot(axes.up));
        r_lo = r_lo.min(r - p.radius);
        r_hi = r_hi.max(r + p.radius);
        u_lo = u_lo.min(u - p.radius);
        u_hi = u_hi.max(u + p.radius);
    }
    mid + axes.right * ((r_lo + r_hi) * 0.5) + axes.up * ((u_lo + u_hi) * 0.5)
}

/// The nearest eye distance from `target` (back along the view) at which every sphere is
/// inside both fields (half-tangents `tan_h`, `tan_v`) with the margin; at least `least`.
fn distance(
    pts: impl IntoIterator<Item = Interest>,
    target: DVec3,
    axes: &Viewer,
    (tan_h, tan_v): (f64, f64),
    least: f64,
) -> f64 {
    let k = 1.0 - MARGIN;
    let mut d = least;
    for p in pts {
        let q = p.centre - target;
        let (r, u, f) = (q.dot(axes.right), q.dot(axes.up), q.dot(axes.forward));
        d = d.max((r.abs() + p.radius) / (tan_h * k) - f + p.radius);
        d = d.max((u.abs() + p.radius) / (tan_v * k) - f + p.radius);
    }
    d
}

/// The finite spheres of `spheres`, as the fitting takes them.
fn interests(spheres: &[(DVec3, f64)]) -> impl Iterator<Item = Interest> + '_ {
    spheres
        .iter()
        .filter(|(p, r)| p.is_finite() && r.is_finite())
        .map(|(p, r)| Interest {
            centre: *p,
            radius: r.max(0.0),
        })
}

/// The point a camera looking along `forward` looks at to centre these spheres (centre,
/// radius) in its view: the middle of their extent across the view. None when there is no
/// finite sphere. With [`distance_along`], the preview's camera of one moment
/// (`preview/framing.rs`).
pub fn centre_along(spheres: &[(DVec3, f64)], forward: DVec3) -> Option<DVec3> {
    let pts: Vec<Interest> = interests(spheres).collect();
    (!pts.is_empty()).then(|| centre(&pts, &axes_of(forward)))
}

/// How far back from `target` along `forward` a mono camera with `c`'s screen (its field) must
/// be for every sphere to be inside its `width` x `height` view, the margin kept free, and the
/// view at least `min_view_m` wide at the target. Allocates nothing.
pub fn distance_along(
    spheres: &[(DVec3, f64)],
    target: DVec3,
    forward: DVec3,
    c: &CameraSettings,
    (width, height): (u32, u32),
    min_view_m: f64,
) -> f64 {
    let tan_h = c.screen_width_m * 0.5 / c.screen_distance_m;
    let tan_v = tan_h * height as f64 / width.max(1) as f64;
    let least = (0.5 * min_view_m / tan_h).max(0.3);
    distance(
        interests(spheres),
        target,
        &axes_of(forward),
        (tan_h, tan_v),
        least,
    )
}

/// The radius of the sphere around G that holds the block.
pub fn block_radius(shape: &common::config::scene::ShapeSpec) -> f64 {
    use common::config::scene::ShapeSpec;
    match shape {
        ShapeSpec::Box { size } | ShapeSpec::Wedge { size } | ShapeSpec::Tetra { size } => {
            0.5 * DVec3::from_array(*size).length()
        }
        ShapeSpec::Hull { vertices } => {
            let n = vertices.len().max(1) as f64;
            let c = vertices
                .iter()
                .fold(DVec3::ZERO, |a, v| a + DVec3::from_array(*v))
                / n;
            vertices
                .iter()
                .map(|v| (DVec3::from_array(*v) - c).length())
                .fold(0.0, f64::max)
        }
    }
}

/// Points along a ballistic flight from `p` at velocity `v` down to the floor: its top and
/// where it lands (and where it starts).
fn flight(p: DVec3, v: DVec3, g: f64, radius: f64) -> Vec<Interest> {
    let mut out = vec![Interest { centre: p, radius }];
    if g <= 0.0 {
        return out;
    }
    if v.y > 0.0 {
        let t = v.y / g;
        out.push(Interest {
            centre: p + v * t - DVec3::Y * (0.5 * g * t * t),
            radius,
        });
    }
    // y(t) = p.y + v.y t - g t^2 / 2 = 0
    let t = (v.y + (v.y * v.y + 2.0 * g * p.y.max(0.0)).sqrt()) / g;
    let land = p + v * t - DVec3::Y * (0.5 * g * t * t);
    out.push(Interest {
        centre: DVec3::new(land.x, 0.0, land.z),
        radius,
    });
    out
}

#[cfg(test)]
mod frame_spheres_tests {
    use super::*;

    /// The preview's camera keeps every given sphere inside its image, whatever the direction
    /// it picks: a tall lift, a far landing, a wide field.
    #[test]
    fn the_fitted_camera_keeps_every_point_inside_the_frame() {
        let (w, h) = (640, 360);
        let sets: [Vec<(DVec3, f64)>; 3] = [
            vec![
                (DVec3::new(0.0, 0.03, 0.0), 0.05),
                (DVec3::new(0.0, 0.6, 0.0), 0.05),
            ],
            vec![
                (DVec3::new(0.0, 0.03, 0.05), 0.05),
                (DVec3::new(0.1, 0.3, -0.3), 0.01),
                (DVec3::new(0.0, 0.0, -0.9), 0.05),
            ],
            (0..64)
                .map(|i| {
                    (
                        DVec3::new((i % 8) as f64 * 0.3 - 1.0, 0.02, (i / 8) as f64 * 0.3 - 1.0),
                        0.03,
                    )
                })
                .collect(),
        ];
        for (k, pts) in sets.iter().enumerate() {
            let c = frame_spheres(pts, &CameraSettings::default(), w, h).unwrap();
            assert_eq!(c.ipd_m, 0.0);
            let [eye, _] = stereo(&c, w, h);
            for (p, _) in pts {
                let (x, y) = eye.project_px(*p, w, h).unwrap();
                assert!(
                    (0.0..w as f64).contains(&x) && (0.0..h as f64).contains(&y),
                    "set {k}: {p} at {x:.1}, {y:.1}"
                );
            }
        }
        assert_eq!(frame_spheres(&[], &CameraSettings::default(), w, h), None);
    }
}
