//! The renderer: draws the newest world state in stereo at the session's frame rate and
//! measures how old each frame's data is when its pixels are done (origin -> photon).
//!
//! The drawing core works without IPC: [`Renderer::new_headless`] takes settings and a scene,
//! [`Renderer::render`] draws a world and hand sample and waits for the GPU,
//! [`Renderer::read_back`] returns the pixels. [`service`] is the process around it.
//!
//! Modules, by concept, each importing only modules listed before it (the module graph has no
//! circle, so each can be read and tested knowing only those it names): [`error`] (the one
//! error type), [`camera`] (the viewer and off-axis stereo), [`settings`] (what the renderer is
//! asked to do), [`mesh`] (static geometry; block meshes over the shapes crate's solids,
//! centred on G), [`pipeline`] (shaders and GPU pipelines), [`draw_list`] (a frame's
//! instances), [`image`] (a frame's pixels), [`renderer`] (device and frame), [`png`],
//! [`output`] (side-by-side, anaglyph, separate), [`preview`] (the animated PNG and GIF, framed
//! on the action), [`overlay`] (the preview's text), [`window`] (winit), [`service`].

pub mod camera;
pub mod draw_list;
pub mod error;
pub mod image;
pub mod mesh;
pub mod output;
pub mod overlay;
pub mod pipeline;
pub mod png;
pub mod preview;
pub mod renderer;
pub mod service;
pub mod settings;
pub mod static_layer;
pub mod window;

pub use camera::CameraSettings;
pub use error::RenderError;
pub use image::Image;
pub use renderer::{FrameTimes, Renderer};
pub use settings::{FramesRequest, OutputMode, RenderSettings};
