//! The live view: a Foxglove WebSocket server (the `foxglove` crate) that serves the session's
//! topics as they flow, with the very schemas and bytes a recording carries (`cdr` messages of
//! `ros2msg` schemas, `recording::layout`), so a panel set up on a recording shows the live
//! session unchanged; plus `/scene`, a `foxglove.SceneUpdate` of the blocks (their shapes and
//! poses) and the hand (finger segments and palm), for the 3D panel.
//!
//! Nothing is encoded for a channel no client subscribes to (`has_sinks`), so a view nobody
//! opened costs the bridge a check per sample. The scene goes out at most 60 times a second.

use std::sync::Arc;

use common::config::Scene;
use common::samples::{BlockMode, BlockState, HandSample, Pose as SamplePose, WorldHeader};
use common::Topic;
use foxglove::schemas::{
    Color, CubePrimitive, LinePrimitive, Point3, Pose, Quaternion, SceneEntity, SceneUpdate,
    TriangleListPrimitive, Vector3,
};
use foxglove::{
    Channel, ChannelBuilder, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};
use glam::DVec3;

/// The scene is sent at most this often (a 3D panel gains nothing from 120 updates a second,
/// and a 1024-block scene is ~60 KB an update).
const SCENE_PERIOD_NS: u64 = 1_000_000_000 / 60;

/// Why the view could not start.
#[derive(Debug)]
pub struct ViewerError(pub String);

impl std::fmt::Display for ViewerError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ViewerError {}

/// A block's shape as the 3D panel draws it.
enum BlockShape {
    Cube([f64; 3]),
    /// Triangles in the block's frame (relative to its centre of gravity), 3 points each.
    Triangles(Vec<Point3>),
}

pub struct Viewer {
    /// The channels' and the server's context: they hold it weakly, so it lives here.
    _context: Arc<foxglove::Context>,
    server: Option<WebSocketServerHandle>,
    channels: Vec<(Topic, Arc<RawChannel>)>,
    scene: Channel<SceneUpdate>,
    shapes: Vec<(String, BlockShape)>,
    last_scene_ns: u64,
    hand: Option<HandSample>,
    palm_points: Vec<DVec3>,
    palm_triangles: Vec<[DVec3; 3]>,
    pub port: u16,
}

fn point(p: [f64; 3]) -> Point3 {
    Point3 {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

fn pose(p: &SamplePose) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: p.position[0],
            y: p.position[1],
            z: p.position[2],
        }),
        orientation: Some(Quaternion {
            x: p.rotation[0],
            y: p.rotation[1],
            z: p.rotation[2],
            w: p.rotation[3],
        }),
    }
}

fn identity() -> Pose {
    pose(&SamplePose::IDENTITY)
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

impl Viewer {
    /// Starts the server on `host:port` (0: any free port; `port` says which) and declares a
    /// channel per topic of `topics` and the scene.
    pub fn start(
        host: &str,
        port: u16,
        scene: &Scene,
        topics: &[Topic],
    ) -> Result<Viewer, ViewerError> {
        let context = foxglove::Context::new();
        let mut channels = Vec::new();
        for &topic in topics {
            let schema = Schema::new(
                topic.schema_name(),
                recording::SCHEMA_ENCODING,
                recording::layout(topic).into_bytes(),
            );
            let channel = ChannelBuilder::new(format!("/{}", topic.name()))
                .message_encoding(recording::MESSAGE_ENCODING)
                .schema(schema)
                .context(&context)
                .build_raw()
                .map_err(|e| {
                    ViewerError(format!("cannot declare the /{} channel: {e}", topic.name()))
                })?;
            channels.push((topic, channel));
        }
        let scene_channel = ChannelBuilder::new("/scene")
            .context(&context)
            .build::<SceneUpdate>();
        let mut shapes = Vec::with_capacity(scene.blocks.len());
        for b in &scene.blocks {
            let shape = match &b.shape {
                common::config::scene::ShapeSpec::Box { size } => BlockShape::Cube(*size),
                spec => {
                    let solid = shapes::Solid::from_spec(spec)
                        .map_err(|p| ViewerError(format!("block {:?}: {p}", b.name)))?;
                    let pts = solid
                        .triangles
                        .iter()
                        .flat_map(|t| t.iter().map(|&i| solid.vertices[i as usize]))
                        .map(|v| point(v.to_array()))
                        .collect();
                    BlockShape::Triangles(pts)
                }
            };
            shapes.push((b.name.clone(), shape));
        }
        let server = WebSocketServer::new()
            .name("handblocks")
            .bind(host, port)
            .context(&context)
            .start_blocking()
            .map_err(|e| {
                ViewerError(format!(
                    "cannot serve the Foxglove view on {host}:{port}: {e} ([viewer] foxglove \
                     names the address; is the port in use?)"
                ))
            })?;
        let port = server.port();
        Ok(Viewer {
            _context: context,
            server: Some(server),
            channels,
            scene: scene_channel,
            shapes,
            last_scene_ns: 0,
            hand: None,
            palm_points: Vec::new(),
            palm_triangles: Vec::new(),
            port,
        })
    }

    /// Sends one message of `topic` (a recording's bytes) to the clients subscribed to it.
    pub fn log(&self, topic: Topic, message: &[u8]) {
        if let Some((_, c)) = self.channels.iter().find(|(t, _)| *t == topic) {
            if c.has_sinks() {
                c.log(message);
            }
        }
    }

    /// One message of `topic` (a recording's bytes): sent on its channel, and the hand and the
    /// world feed the scene.
    pub fn observe(&mut self, topic: Topic, message: &[u8], now_ns: u64) {
        self.log(topic, message);
        match topic {
            Topic::Hand => {
                if let Ok(hand) = recording::decode_sample::<HandSample>(topic, message) {
                    self.hand = Some(hand);
                }
            }
            Topic::World => {
                if let Ok((_, body)) = recording::decode_slice::<WorldHeader>(topic, message) {
                    let size = std::mem::size_of::<BlockState>();
                    let n = body.len() / size;
                    // SAFETY: `body` holds `n` whole block states (decode_slice checked its
                    // length); plain old data, read unaligned.
                    self.world(now_ns, n, |i| unsafe {
                        std::ptr::read_unaligned(body[i * size..].as_ptr() as *const BlockState)
                    });
                }
            }
            _ => {}
        }
    }

    /// A world state: the scene is sent if a client wants it and the last went out long enough
    /// ago. `block(i)` is block `i`'s state.
    fn world(&mut self, now_ns: u64, blocks: usize, block: impl Fn(usize) -> BlockState) {
        if !self.scene.has_sinks() || now_ns.saturating_sub(self.last_scene_ns) < SCENE_PERIOD_NS {
            return;
        }
        self.last_scene_ns = now_ns;
        let mut entities = Vec::with_capacity(blocks + 1);
        for (i, (name, shape)) in self.shapes.iter().enumerate().take(blocks) {
            let state = block(i);
            let p = pose(&state.pose);
            // Blocks the hand moves (pushed, grasped, carried) in orange, the others grey-blue.
            let c = if matches!(
                state.mode(),
                BlockMode::Pushed | BlockMode::Grasped | BlockMode::Carried
            ) {
                color(0.95, 0.6, 0.2, 1.0)
            } else {
                color(0.55, 0.62, 0.75, 1.0)
            };
            let mut e = SceneEntity {
                frame_id: "world".into(),
                id: name.clone(),
                ..Default::default()
            };
            match shape {
                BlockShape::Cube(size) => e.cubes.push(CubePrimitive {
                    pose: Some(p),
                    size: Some(Vector3 {
                        x: size[0],
                        y: size[1],
                        z: size[2],
                    }),
                    color: c,
                }),
                BlockShape::Triangles(points) => e.triangles.push(TriangleListPrimitive {
                    pose: Some(p),
                    points: points.clone(),
                    color: c,
                    ..Default::default()
                }),
            }
            entities.push(e);
        }
        if let Some(hand) = self.hand {
            entities.push(self.hand_entity(&hand));
        }
        self.scene.log(&SceneUpdate {
            deletions: Vec::new(),
            entities,
        });
    }

    fn hand_entity(&mut self, hand: &HandSample) -> SceneEntity {
        let mut e = SceneEntity {
            frame_id: "world".into(),
            id: "hand".into(),
            ..Default::default()
        };
        let skin = color(0.93, 0.76, 0.62, 0.9);
        for f in 0..(hand.finger_count as usize).min(hand.finger_points.len()) {
            e.lines.push(LinePrimitive {
                r#type: 0, // a line strip, knuckle to tip
                pose: Some(identity()),
                thickness: 2.0 * hand.finger_radius[f],
                scale_invariant: false,
                points: hand.finger(f).iter().map(|p| point(*p)).collect(),
                color: skin,
                ..Default::default()
            });
        }
        self.palm_points.clear();
        self.palm_points
            .extend(hand.palm().iter().map(|p| DVec3::from_array(*p)));
        if !self.palm_points.is_empty() {
            shapes::hull_triangles_into(&self.palm_points, &mut self.palm_triangles);
            e.triangles.push(TriangleListPrimitive {
                pose: Some(identity()),
                points: self
                    .palm_triangles
                    .iter()
                    .flat_map(|t| t.iter().map(|v| point(v.to_array())))
                    .collect(),
                color: skin,
                ..Default::default()
            });
        }
        e
    }

    /// Stops the server (clients see the connection close).
    pub fn stop(mut self) {
        if let Some(s) = self.server.take() {
            let _ = s.stop();
        }
    }
}
