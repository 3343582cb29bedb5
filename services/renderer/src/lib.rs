//! The renderer: draws the newest world state in stereo at the session's frame rate and
//! measures how old each frame's data is when its pixels are done (origin -> photon).
//!
//! The drawing core works without IPC: [`Renderer::new_headless`] takes settings and a scene,
//! [`Renderer::render`] draws a world and hand sample and waits for the GPU,
//! [`Renderer::read_back`] returns the pixels. [`service`] is the process around it.
//!
//! Modules, by concept: [`camera`] (off-axis stereo), [`mesh`] (static geometry; block meshes
//! over the shapes crate's solids, centred on G), [`draw_list`] (a frame's instances),
//! [`pipeline`] (shaders and GPU pipelines), [`renderer`] (device and frame), [`output`]
//! (side-by-side, anaglyph, separate), [`png`], [`window`] (winit), [`service`].

pub mod camera;
pub mod draw_list;
pub mod mesh;
pub mod output;
pub mod pipeline;
pub mod png;
pub mod preview;
pub mod renderer;
pub mod service;
pub mod settings;
pub mod window;

pub use output::Image;
pub use renderer::{FrameTimes, RenderError, Renderer};
pub use settings::{CameraSettings, FramesRequest, OutputMode, RenderSettings};
