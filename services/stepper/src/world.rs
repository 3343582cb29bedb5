//! Minimal placeholder world: R7 (gravity, inertia) and R8 (floor rest) for boxes only.
//! Replaced by the full model.

use common::config::scene::ShapeSpec;
use common::config::Scene;
use common::{BlockMode, BlockState, HandSample, Pose, WorldSample, MAX_BLOCKS};
use glam::{DQuat, DVec3};

#[derive(Debug)]
pub struct WorldError(pub String);
impl std::fmt::Display for WorldError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for WorldError {}

#[derive(Debug, Clone, PartialEq)]
pub struct Event;

struct Block {
    name: String,
    half: DVec3,
    position: DVec3,
    rotation: DQuat,
    v: DVec3,
    mode: BlockMode,
}

pub struct World {
    blocks: Vec<Block>,
    g_step: DVec3,
    steps: u64,
}

impl World {
    pub fn new(scene: &Scene) -> Result<World, WorldError> {
        let dt = 1.0 / scene.world.step_hz;
        let blocks = scene
            .blocks
            .iter()
            .take(MAX_BLOCKS)
            .map(|b| {
                let size = match &b.shape {
                    ShapeSpec::Box { size }
                    | ShapeSpec::Wedge { size }
                    | ShapeSpec::Tetra { size } => *size,
                    ShapeSpec::Hull { .. } => [0.1; 3],
                };
                Block {
                    name: b.name.clone(),
                    half: DVec3::from_array(size) / 2.0,
                    position: DVec3::from_array(b.position),
                    rotation: DQuat::from_array(b.rotation),
                    v: DVec3::from_array(b.velocity) * dt,
                    mode: BlockMode::Free,
                }
            })
            .collect();
        Ok(World {
            blocks,
            g_step: DVec3::new(0.0, -scene.world.gravity * dt * dt, 0.0),
            steps: 0,
        })
    }

    pub fn step(&mut self, _hand: Option<&HandSample>) {
        for b in &mut self.blocks {
            if b.mode == BlockMode::Resting {
                continue;
            }
            let d = b.v + self.g_step;
            b.position += d;
            b.v = d;
            let lowest = b.position.y - b.half.y;
            if lowest <= 0.0 {
                b.position.y -= lowest;
                b.v = DVec3::ZERO;
                b.mode = BlockMode::Resting;
            }
        }
        self.steps += 1;
    }

    pub fn write_sample(&self, out: &mut WorldSample) {
        out.block_count = self.blocks.len() as u32;
        for (o, b) in out.blocks.iter_mut().zip(&self.blocks) {
            *o = BlockState {
                pose: Pose {
                    position: b.position.to_array(),
                    rotation: b.rotation.to_array(),
                },
                mode: b.mode as u32,
                _reserved: 0,
            };
        }
        out.grasped_block = -1;
    }

    pub fn steps(&self) -> u64 {
        self.steps
    }

    pub fn events(&self) -> &[Event] {
        &[]
    }

    pub fn block_names(&self) -> impl Iterator<Item = &str> {
        self.blocks.iter().map(|b| b.name.as_str())
    }
}
