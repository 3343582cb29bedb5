//! What the renderer is asked to do: image size, output mode, the viewer
//! ([`CameraSettings`], with the stereo geometry in [`crate::camera`]), shadows, frame files.
//!
//! `common`'s `[renderer]` section holds only `mode`, `width` and `height` today; the rest lives
//! here with defaults until the session file grows the keys (see [`RenderSettings::from_session`]).

use std::path::PathBuf;

use common::config::session::RendererSettings;

use crate::camera::{frame_scene, CameraSettings};

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
    /// `eye` nor `target` (see [`frame_scene`]).
    pub fn from_session_framed(
        r: &RendererSettings,
        scene: &common::config::Scene,
    ) -> RenderSettings {
        let mut s = RenderSettings::from_session(r);
        if r.auto_camera {
            let (eye, target) = frame_scene(scene, &s.camera, s.width, s.height);
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
