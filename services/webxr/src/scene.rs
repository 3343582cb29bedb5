//! The scene as the page draws it ([`webxr_wire::page::Scene`]), made of the session's: each
//! block's hull (its own frame, about its centre of gravity, as the world's poses place it),
//! its name and colour; the floor; the hands the session takes and its offset.

use common::config::session::WebxrSource;
use common::config::Session;
use webxr_wire::page::{Scene, SceneBlock, SceneOp};

/// A block whose shape makes no solid.
#[derive(Debug, thiserror::Error)]
#[error("{}: block {:?}: {}", .file.display(), .block, .problem)]
pub struct SceneError {
    pub file: std::path::PathBuf,
    pub block: String,
    pub problem: String,
}

/// The scene message of `session`, whose source is `settings`.
pub fn scene(session: &Session, settings: &WebxrSource) -> Result<Scene, SceneError> {
    let colours = common::config::colors::block_colors(&session.scene);
    let mut blocks = Vec::with_capacity(session.scene.blocks.len());
    for (b, colour) in session.scene.blocks.iter().zip(colours) {
        let solid = shapes::Solid::from_spec(&b.shape).map_err(|problem| SceneError {
            file: session.scene_file.clone(),
            block: b.name.clone(),
            problem,
        })?;
        blocks.push(SceneBlock {
            color: colour.map(f64::from),
            indices: solid.triangles.iter().flatten().copied().collect(),
            name: b.name.clone(),
            vertices: solid.vertices.iter().flat_map(|v| v.to_array()).collect(),
        });
    }
    Ok(Scene {
        blocks,
        floor_y: 0.0,
        hand: settings.hand.into(),
        offset: settings.offset,
        op: SceneOp::Scene,
        session: session.file.display().to_string(),
        step_hz: session.scene.world.step_hz,
    })
}
