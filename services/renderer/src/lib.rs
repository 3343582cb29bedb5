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

/// The renderer's process (the stereo view), as `handblocks service renderer` runs it: its
/// frames into `--frames-dir` (a restarted renderer into a folder of its own there, numbering
/// again, so that none of the dead one's is overwritten) and its preview into `--preview`.
pub struct Process;

impl common::node::Process for Process {
    const STAGE: common::Stage = common::Stage::Renderer;
    type Error = RenderError;
    fn run(
        session: &common::config::Session,
        bus: &common::bus::Bus,
        launch: &common::node::Launch,
    ) -> Result<(), Self::Error> {
        service::run_with_preview(
            session,
            bus,
            RenderSettings::from_session_framed(&session.renderer, &session.scene),
            launch.frames_dir.as_ref().map(|dir| FramesRequest {
                dir: launch.output_of(common::Stage::Renderer, dir),
                every_nth: session.renderer.frames_every,
            }),
            launch.preview.clone(),
        )
    }
}
