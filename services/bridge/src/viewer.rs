//! The live view: a Foxglove WebSocket server (the `foxglove` crate, behind [`crate::gate`],
//! which lets in clients of either subprotocol name) that serves the session's topics as they
//! flow, with the very schemas, bytes and channel names a recording carries (`/world`, ... as
//! `cdr` messages of `ros2msg` schemas, `recording::layout`), so a layout made on a recording
//! shows the live session unchanged; plus `/scene`, the blocks, the floor and the hand (a
//! two-hand session's left hand its own entity, `scene_view::LEFT_HAND_ID`) as a
//! `foxglove.SceneUpdate` in Foxglove's z-up frame (`scene_view`), and `/tf`, the hand as a
//! tree of frames (`world` -> `hand` -> each finger's joints, `foxglove.FrameTransforms`,
//! `scene_view::HandFrames`), both of which recordings carry too.
//!
//! A topic's channel is declared when its first sample arrives, so a client is never offered a
//! topic this session does not carry. Nothing is encoded for a channel no client subscribes
//! to (`has_sinks`), so a view nobody opened costs the bridge a check per sample. The scene
//! and the hand's frames go out at most 60 times a second, together (the frames stamped with
//! the time they are sent, which is their message's log time).
//!
//! What a client may cost is bounded: the gate caps the clients (`[viewer] foxglove_clients`)
//! and closes one that stops taking bytes; the server queues at most [`BACKLOG_BYTES`] of
//! messages a client (the oldest dropped first), where the `foxglove` crate's default of 1024
//! messages is ~64 MiB a client on a 1024-block field.

use std::sync::Arc;

use common::config::Scene;
use common::samples::{BlockState, HandSample, WorldHeader};
use common::Topic;
use foxglove::schemas::{FrameTransforms, SceneUpdate};
use foxglove::{
    Channel, ChannelBuilder, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};
use scene_view::SceneView;

use crate::gate::Gate;

/// The scene is sent at most this often (a 3D panel gains nothing from 120 updates a second,
/// and a 1024-block scene is ~60 KB an update).
const SCENE_PERIOD_NS: u64 = 1_000_000_000 / 60;

/// About how many bytes of messages the server queues for a client that cannot take them as
/// fast as they come (a slow link, or one that stopped reading), before it drops the oldest:
/// a view is live, so old samples are worth less than memory. The server counts messages, so
/// this is divided by the scene's largest message ([`backlog_messages`]).
pub const BACKLOG_BYTES: usize = 4 << 20;
/// The fewest messages queued a client, whatever their size: the server's control messages
/// (the channels' advertisements) share the bound, and a client whose control queue fills is
/// dropped.
const MIN_BACKLOG: usize = 16;
/// The most, the `foxglove` crate's default (small messages cost little).
const MAX_BACKLOG: usize = 1024;
/// The clients served at once when the session names no `[viewer] foxglove_clients`.
pub const DEFAULT_CLIENTS: usize = common::config::remote::DEFAULT_FOXGLOVE_CLIENTS;

/// How many messages the server queues a client: [`BACKLOG_BYTES`] over the largest message
/// the scene makes (its world or its `/scene` update, a quarter more for the hand's entities
/// and the labels that come and go), within [`MIN_BACKLOG`]..=[`MAX_BACKLOG`].
fn backlog_messages(scene: &Scene, view: &SceneView) -> usize {
    let world = recording::slice_message_bytes(Topic::World, scene.blocks.len()).unwrap_or(0);
    let update = foxglove::Encode::encoded_len(view.update()).unwrap_or(0);
    let largest = world.max(update).saturating_mul(5) / 4;
    (BACKLOG_BYTES / largest.max(1)).clamp(MIN_BACKLOG, MAX_BACKLOG)
}

/// Why the view could not start.
#[derive(Debug)]
pub struct ViewerError(pub String);

impl std::fmt::Display for ViewerError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ViewerError {}

pub struct Viewer {
    /// The channels' and the server's context: they hold it weakly, so it lives here.
    context: Arc<foxglove::Context>,
    server: Option<WebSocketServerHandle>,
    gate: Option<Gate>,
    /// The topics it may serve, and the channel of each once its first sample came.
    served: Vec<Topic>,
    channels: [Option<Arc<RawChannel>>; Topic::ALL.len()],
    scene: Channel<SceneUpdate>,
    /// The hand's frames (`/tf`), sent with the scene.
    tf: Channel<FrameTransforms>,
    view: SceneView,
    last_scene_ns: u64,
    /// The port clients connect to (the gate's).
    pub port: u16,
}

impl Viewer {
    /// [`Viewer::start_capped`] with the default cap of clients ([`DEFAULT_CLIENTS`]).
    pub fn start(
        host: &str,
        port: u16,
        scene: &Scene,
        topics: &[Topic],
    ) -> Result<Viewer, ViewerError> {
        Viewer::start_capped(host, port, scene, topics, DEFAULT_CLIENTS)
    }

    /// Starts the server on `host:port` (0: any free port; `port` says which), serving at most
    /// `clients` clients at once (`[viewer] foxglove_clients`); the topics of `topics` are
    /// served once they carry samples, the scene at once.
    pub fn start_capped(
        host: &str,
        port: u16,
        scene: &Scene,
        topics: &[Topic],
        clients: usize,
    ) -> Result<Viewer, ViewerError> {
        let context = foxglove::Context::new();
        let scene_channel = ChannelBuilder::new(scene_view::CHANNEL)
            .context(&context)
            .build::<SceneUpdate>();
        let tf_channel = ChannelBuilder::new(scene_view::TF_CHANNEL)
            .context(&context)
            .build::<FrameTransforms>();
        let view = SceneView::new(scene).map_err(|e| ViewerError(e.to_string()))?;
        // The server itself listens on a loopback port only the gate reaches.
        let server = WebSocketServer::new()
            .name("handblocks")
            .bind("127.0.0.1", 0)
            .message_backlog_size(backlog_messages(scene, &view))
            .context(&context)
            .start_blocking()
            .map_err(|e| ViewerError(format!("cannot start the Foxglove server: {e}")))?;
        let inner = std::net::SocketAddr::from(([127, 0, 0, 1], server.port()));
        let gate = Gate::start(host, port, inner, clients).map_err(|e| {
            ViewerError(format!(
                "cannot serve the Foxglove view on {host}:{port}: {e} ([viewer] foxglove \
                 names the address; is the port in use?)"
            ))
        })?;
        let port = gate.port();
        Ok(Viewer {
            context,
            server: Some(server),
            gate: Some(gate),
            served: topics.to_vec(),
            channels: std::array::from_fn(|_| None),
            scene: scene_channel,
            tf: tf_channel,
            view,
            last_scene_ns: 0,
            port,
        })
    }

    /// `topic`'s channel, declared on its first sample.
    fn channel(&mut self, topic: Topic) -> Option<&Arc<RawChannel>> {
        let slot = &mut self.channels[topic as usize];
        if slot.is_none() && self.served.contains(&topic) {
            let schema = Schema::new(
                topic.schema_name(),
                recording::SCHEMA_ENCODING,
                recording::layout(topic).into_bytes(),
            );
            // A channel that cannot be declared is not served; the rest still are.
            *slot = ChannelBuilder::new(topic.channel())
                .message_encoding(recording::MESSAGE_ENCODING)
                .schema(schema)
                .context(&self.context)
                .build_raw()
                .ok();
        }
        slot.as_ref()
    }

    /// Sends one message of `topic` (a recording's bytes) to the clients subscribed to it.
    pub fn log(&mut self, topic: Topic, message: &[u8]) {
        if let Some(c) = self.channel(topic) {
            if c.has_sinks() {
                c.log(message);
            }
        }
    }

    /// One message of `topic` (a recording's bytes): sent on its channel, and the hand and the
    /// world feed the scene and the hand's frames.
    pub fn observe(&mut self, topic: Topic, message: &[u8], now_ns: u64) {
        self.log(topic, message);
        match topic {
            Topic::Hand => scene_hand(&mut self.view, message),
            Topic::World => {
                let (scene, tf) = (self.scene.has_sinks(), self.tf.has_sinks());
                if !(scene || tf) || now_ns.saturating_sub(self.last_scene_ns) < SCENE_PERIOD_NS {
                    return;
                }
                if let Ok((_, body)) = recording::decode_slice::<WorldHeader>(topic, message) {
                    self.last_scene_ns = now_ns;
                    let size = std::mem::size_of::<BlockState>();
                    // SAFETY: `body` holds `len / size` whole block states (decode_slice
                    // checked its length); plain old data, read unaligned.
                    self.view.set_world(body.len() / size, |i| unsafe {
                        std::ptr::read_unaligned(body[i * size..].as_ptr() as *const BlockState)
                    });
                    if scene {
                        self.scene.log(self.view.update());
                    }
                    if tf && !self.view.frames().is_empty() {
                        let unix_ns = unix_now_ns();
                        self.view.frames_mut().stamp(unix_ns);
                        self.tf.log_with_time(self.view.frames().message(), unix_ns);
                    }
                }
            }
            _ => {}
        }
    }

    /// Stops the server (clients see the connection close).
    pub fn stop(mut self) {
        if let Some(g) = self.gate.take() {
            g.stop();
        }
        if let Some(s) = self.server.take() {
            let _ = s.stop();
        }
    }
}

/// Now, in nanoseconds since the Unix epoch (the live view's log times); 0 on a clock set
/// before 1970.
fn unix_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// A `hand` message (a recording's bytes) into the scene. Both hands of a two-hand session
/// come here: the view keeps each side's newest (its `side`), the left hand drawn as an
/// entity of its own (`scene_view::LEFT_HAND_ID`).
fn scene_hand(view: &mut SceneView, message: &[u8]) {
    if let Ok(hand) = recording::decode_sample::<HandSample>(Topic::Hand, message) {
        view.set_hand(&hand);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A two-hand source's hand messages, the right then the left, make two hand entities;
    /// a one-hand source's, one.
    #[test]
    fn a_left_hand_message_is_drawn_as_its_own_entity() {
        let push = scene("push.toml");
        let hand = |side: common::HandSide, x: f64| {
            let mut h = HandSample {
                finger_count: 1,
                side: side.code(),
                ..Default::default()
            };
            h.finger_point_count[0] = 2;
            h.finger_points[0][..2].copy_from_slice(&[[x, 0.2, 0.0], [x, 0.2, 0.03]]);
            let mut bytes = Vec::new();
            recording::encode_sample(&h, &mut bytes);
            bytes
        };
        let ids = |v: &SceneView| -> Vec<String> {
            v.update().entities.iter().map(|e| e.id.clone()).collect()
        };
        let blocks = push.blocks.len();
        let mut one = SceneView::new(&push).expect("a view");
        scene_hand(&mut one, &hand(common::HandSide::Right, 0.0));
        one.set_world(blocks, |_| BlockState::default());
        let mut two = SceneView::new(&push).expect("a view");
        scene_hand(&mut two, &hand(common::HandSide::Right, 0.0));
        scene_hand(&mut two, &hand(common::HandSide::Left, -0.3));
        two.set_world(blocks, |_| BlockState::default());
        let (one_ids, two_ids) = (ids(&one), ids(&two));
        assert_eq!(
            one_ids.last().map(String::as_str),
            Some(scene_view::HAND_ID)
        );
        assert_eq!(two_ids[..one_ids.len()], one_ids[..]);
        assert_eq!(
            two_ids[one_ids.len()..],
            [scene_view::LEFT_HAND_ID.to_string()]
        );
        let left = &two.update().entities[one_ids.len()];
        assert_eq!(left.lines[0].points.first().map(|p| p.x), Some(-0.3));
    }

    fn scene(name: &str) -> Scene {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes");
        Scene::load(&dir.join(name)).expect("the scene loads")
    }

    /// A 1024-block field queues tens of its ~64 KiB worlds a client, not the crate's 1024; a
    /// small scene keeps the crate's 1024 small messages.
    #[test]
    fn the_backlog_is_a_few_mib_of_the_scenes_largest_message() {
        let field = scene("field-1024.toml");
        let n = backlog_messages(&field, &SceneView::new(&field).expect("a view"));
        let world = recording::slice_message_bytes(Topic::World, 1024).expect("a size");
        assert!((MIN_BACKLOG..=64).contains(&n), "{n} messages");
        assert!(n * world <= BACKLOG_BYTES, "{n} x {world} bytes");
        let push = scene("push.toml");
        let n = backlog_messages(&push, &SceneView::new(&push).expect("a view"));
        assert_eq!(n, MAX_BACKLOG);
    }
}
