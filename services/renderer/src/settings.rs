//! What the renderer is asked to do: image size, output mode, stereo geometry, viewpoint.
//!
//! `common`'s `[renderer]` section holds only `mode`, `width` and `height` today; the rest lives
//! here with defaults until the session file grows the keys (see [`RenderSettings::from_session`]).

use std::path::PathBuf;

use common::config::session::RendererSettings;

/// How the two eyes' images reach the user.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OutputMode {
    /// Left eye in the left half, right eye in the right half: one image 2W x H (cross-eyed
    /// viewing swaps them; free viewing and most stereo players take this layout).
    #[default]
    SideBySide,
    /// Red-cyan anaglyph, W x H: anyone with cheap glasses sees the depth, no shutter glasses.
    Anaglyph,
    /// Two W x H images, one per eye (shutter glasses, HMD, or analysis).
    Separate,
}

impl OutputMode {
    /// The session-file spelling.
    pub fn name(self) -> &'static str {
        match self {
            OutputMode::SideBySide => "side-by-side",
            OutputMode::Anaglyph => "anaglyph",
            OutputMode::Separate => "separate",
        }
    }

    pub fn from_name(s: &str) -> Option<OutputMode> {
        match s {
            "side-by-side" => Some(OutputMode::SideBySide),
            "anaglyph" => Some(OutputMode::Anaglyph),
            "separate" => Some(OutputMode::Separate),
            _ => None,
        }
    }
}

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

/// Everything [`crate::Renderer`] needs.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    /// Per eye, pixels.
    pub width: u32,
    pub height: u32,
    pub output: OutputMode,
    pub camera: CameraSettings,
    /// Planar shadows of blocks and hand on the floor (they make heights readable).
    pub shadows: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 640,
            height: 480,
            output: OutputMode::SideBySide,
            camera: CameraSettings::default(),
            shadows: true,
        }
    }
}

impl RenderSettings {
    /// The settings a session's `[renderer]` names; keys the session file does not have yet
    /// take their defaults.
    pub fn from_session(r: &RendererSettings) -> RenderSettings {
        RenderSettings {
            width: r.width,
            height: r.height,
            output: OutputMode::from_name(&r.output).unwrap_or_default(),
            camera: CameraSettings {
                eye: r.eye,
                target: r.target,
                ipd_m: r.ipd_mm / 1000.0,
                screen_distance_m: r.screen_distance_m,
                screen_width_m: r.screen_width_m,
                ..CameraSettings::default()
            },
            shadows: r.shadows,
        }
    }

    /// [`Self::from_session`], with the camera framing `scene` when the session gives neither
    /// `eye` nor `target` (see [`crate::camera::frame_scene`]).
    pub fn from_session_framed(
        r: &RendererSettings,
        scene: &common::config::Scene,
    ) -> RenderSettings {
        let mut s = RenderSettings::from_session(r);
        if r.auto_camera {
            let (eye, target) = crate::camera::frame_scene(scene, &s.camera, s.width, s.height);
            s.camera.eye = eye;
            s.camera.target = target;
        }
        s
    }

    /// Checks what a user could get wrong, naming the setting and its range.
    pub fn validate(&self) -> Result<(), String> {
        let c = &self.camera;
        let finite = c.eye.iter().chain(c.target.iter()).all(|v| v.is_finite());
        if !finite {
            return Err("camera eye and target must be finite".into());
        }
        let d: f64 = (0..3).map(|i| (c.target[i] - c.eye[i]).powi(2)).sum();
        if d.sqrt() < 1e-6 {
            return Err("camera target must differ from the eye point".into());
        }
        let checks = [
            ("width", self.width as f64, 16.0, 8192.0),
            ("height", self.height as f64, 16.0, 8192.0),
            ("ipd_m", c.ipd_m, 0.0, 0.5),
            ("screen_distance_m", c.screen_distance_m, 0.05, 100.0),
            ("screen_width_m", c.screen_width_m, 0.01, 100.0),
            ("near_m", c.near_m, 1e-4, 10.0),
            ("far_m", c.far_m, c.near_m * 1.001, 1e6),
        ];
        for (name, v, lo, hi) in checks {
            if !(v >= lo && v <= hi) {
                return Err(format!("{name} = {v}; allowed: {lo} to {hi}"));
            }
        }
        Ok(())
    }
}

/// `--frames-dir DIR`: write every `every_nth` rendered frame as PNG into `dir`
/// (`frame_NNNNNN.png`; separate mode: `frame_NNNNNN_left.png` and `_right.png`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramesRequest {
    pub dir: PathBuf,
    /// 1 = every frame.
    pub every_nth: u32,
}
