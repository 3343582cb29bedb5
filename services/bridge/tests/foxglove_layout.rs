//! The shipped Foxglove layout (`config/foxglove/handblocks-layout.json`) against what we
//! serve: it parses as a layout (every panel of the tree configured, every configured panel in
//! the tree), every topic it names is a channel of the live view and of recordings, and every
//! message path's fields exist, with those names and shapes, in the schema that channel
//! advertises (the `ros2msg` text `recording::layout` writes, read here as Foxglove reads it).

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use common::{Stage, Topic};
use serde_json::Value;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn layout() -> Value {
    let path = repo().join("config/foxglove/handblocks-layout.json");
    let text = std::fs::read_to_string(&path).expect("the layout file");
    serde_json::from_str(&text).expect("the layout is JSON")
}

/// The topics the live view may serve: those the bridge reads (the recording's channels).
fn sample_channels() -> Vec<Topic> {
    Topic::ALL
        .into_iter()
        .filter(|t| t.readers().contains(&Stage::Bridge))
        .collect()
}

/// One field of a ROS 2 message definition: its name, its type without array brackets, and
/// its array length (`Some(None)` for an unbounded sequence, `None` for a single value).
#[derive(Debug, Clone)]
struct Field {
    ty: String,
    array: Option<Option<usize>>,
}

/// The message definitions of a `ros2msg` schema as Foxglove's parser splits them: the top
/// message (named `top`), then each `MSG: name` after a line of `=`; constants
/// (`uint32 MODE_GRASPED=4`) and comments are not fields.
fn parse_ros2msg(top: &str, text: &str) -> BTreeMap<String, BTreeMap<String, Field>> {
    let mut out: BTreeMap<String, BTreeMap<String, Field>> = BTreeMap::new();
    let mut current = top.to_string();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() || line.chars().all(|c| c == '=') {
            continue;
        }
        if let Some(name) = line.strip_prefix("MSG:") {
            current = name.trim().to_string();
            continue;
        }
        let mut words = line.split_whitespace();
        let (Some(ty), Some(name)) = (words.next(), words.next()) else {
            panic!("not a field: {line:?}");
        };
        if name.contains('=') {
            continue; // a constant
        }
        let (base, array) = match ty.split_once('[') {
            Some((base, rest)) => {
                let n = rest.trim_end_matches(']');
                (base, Some(n.parse().ok()))
            }
            None => (ty, None),
        };
        out.entry(current.clone()).or_default().insert(
            name.to_string(),
            Field {
                ty: base.to_string(),
                array,
            },
        );
    }
    out
}

const PRIMITIVES: [&str; 10] = [
    "bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float64",
];

/// Message path modifiers a numeric series may end with (Foxglove's FoxQL functions).
const MODIFIERS: [&str; 6] = ["@div(", "@mul(", "@add(", "@sub(", "@abs", "@negative"];

/// Checks message path `path` (`/world.blocks[0].pose.position[1]`) against the channels:
/// its topic is served and each field exists in its schema with the indexing used; the path
/// ends on a number when `numeric`. Returns the topic.
fn check_path(path: &str, numeric: bool) -> String {
    let channels = sample_channels();
    // The longest channel name the path starts with, followed by a field or nothing.
    let topic = channels
        .iter()
        .filter(|t| {
            path.strip_prefix(t.channel())
                .is_some_and(|rest| rest.is_empty() || rest.starts_with('.'))
        })
        .max_by_key(|t| t.channel().len())
        .unwrap_or_else(|| panic!("{path:?}: no channel of ours ({channels:?}) starts it"));
    let schema = parse_ros2msg(topic.schema_name(), &recording::layout(*topic));
    let rest = &path[topic.channel().len()..];
    let mut ty = topic.schema_name().to_string();
    let mut segments = rest.split('.').skip(1).peekable();
    let mut on_array = false;
    while let Some(segment) = segments.next() {
        if segment.starts_with('@') {
            assert!(
                MODIFIERS.iter().any(|m| segment.starts_with(m)),
                "{path:?}: modifier {segment:?} is not one we use"
            );
            assert!(
                PRIMITIVES.contains(&ty.as_str()) && !on_array,
                "{path:?}: {segment} applies to a number, not {ty}"
            );
            if let Some(arg) = segment.split_once('(').map(|(_, a)| a) {
                let arg = arg.strip_suffix(')').expect("a closed argument");
                arg.parse::<f64>()
                    .unwrap_or_else(|_| panic!("{path:?}: {arg:?} is not a number"));
            }
            continue;
        }
        assert!(!on_array, "{path:?}: an array before {segment:?}: index it");
        let (name, index) = match segment.split_once('[') {
            Some((name, index)) => (
                name,
                Some(index.strip_suffix(']').expect("a closed [index]")),
            ),
            None => (segment, None),
        };
        let fields = schema
            .get(&ty)
            .unwrap_or_else(|| panic!("{path:?}: {ty} is not a message of {topic:?}'s schema"));
        let field = fields.get(name).unwrap_or_else(|| {
            panic!(
                "{path:?}: {ty} has no field {name:?} (its fields: {:?})",
                fields.keys().collect::<Vec<_>>()
            )
        });
        on_array = match (field.array, index) {
            (None, None) => false,
            (None, Some(_)) => panic!("{path:?}: {name} is not an array"),
            (Some(_), None) => true,
            (Some(len), Some(i)) => {
                let i: usize = i
                    .parse()
                    .unwrap_or_else(|_| panic!("{path:?}: [{i}] is not an index"));
                if let Some(len) = len {
                    assert!(i < len, "{path:?}: {name} has {len} elements");
                }
                false
            }
        };
        ty = field.ty.clone();
        if segments.peek().is_some_and(|s| !s.starts_with('@')) {
            assert!(
                !PRIMITIVES.contains(&ty.as_str()),
                "{path:?}: {name} is a {ty}, with no fields"
            );
        }
    }
    if numeric {
        assert!(
            PRIMITIVES.contains(&ty.as_str()) && !on_array,
            "{path:?} ends on {ty}{}, not a number",
            if on_array { "[]" } else { "" }
        );
    }
    topic.channel().to_string()
}

/// The panel ids of a layout tree (a panel id, or a split of two).
fn panels_of(node: &Value, out: &mut BTreeSet<String>) {
    match node {
        Value::String(id) => {
            out.insert(id.clone());
        }
        Value::Object(split) => {
            assert!(
                matches!(split["direction"].as_str(), Some("row" | "column")),
                "a split's direction: {node}"
            );
            let pct = split["splitPercentage"].as_f64().unwrap_or(50.0);
            assert!((0.0..=100.0).contains(&pct), "{node}");
            panels_of(&split["first"], out);
            panels_of(&split["second"], out);
        }
        other => panic!("not a layout node: {other}"),
    }
}

#[test]
fn the_shipped_layout_names_only_our_channels_and_fields() {
    // The channels of the view beside the topics are the same strings live and recorded.
    assert_eq!(scene_view::CHANNEL, recording::SCENE_CHANNEL);
    assert_eq!(scene_view::TF_CHANNEL, recording::TF_CHANNEL);

    let v = layout();
    let configs = v["configById"].as_object().expect("configById");
    let mut in_tree = BTreeSet::new();
    panels_of(&v["layout"], &mut in_tree);
    let configured: BTreeSet<String> = configs.keys().cloned().collect();
    assert_eq!(in_tree, configured, "every panel placed and configured");
    assert!(v["playbackConfig"].is_object());

    let mut topics = BTreeSet::new();
    let mut kinds = BTreeSet::new();
    for (id, config) in configs {
        let (kind, _) = id.split_once('!').expect("a panel id is TYPE!NAME");
        kinds.insert(kind.to_string());
        match kind {
            "3D" => {
                // The frame the scene is drawn in and the /tf tree's root.
                assert_eq!(config["followTf"], scene_view::FRAME_ID, "{id}");
                let shown: BTreeSet<&str> = config["topics"]
                    .as_object()
                    .expect("3D topics")
                    .keys()
                    .map(String::as_str)
                    .collect();
                assert_eq!(
                    shown,
                    BTreeSet::from([scene_view::CHANNEL, scene_view::TF_CHANNEL]),
                    "{id}"
                );
                for layer in config["layers"].as_object().into_iter().flatten() {
                    if let Some(frame) = layer.1["frameId"].as_str() {
                        assert_eq!(frame, scene_view::FRAME_ID, "{id}: layer {}", layer.0);
                    }
                }
                topics.extend(shown.iter().map(|s| s.to_string()));
            }
            "Plot" | "StateTransitions" => {
                let paths = config["paths"].as_array().expect("paths");
                assert!(!paths.is_empty(), "{id}");
                for p in paths {
                    let value = p["value"].as_str().expect("a path's value");
                    assert_eq!(p["timestampMethod"], "receiveTime", "{id}: {value}");
                    topics.insert(check_path(value, true));
                }
            }
            "RawMessages" => {
                let value = config["topicPath"].as_str().expect("topicPath");
                topics.insert(check_path(value, false));
            }
            other => panic!("{id}: a {other} panel the test does not know"),
        }
    }
    assert!(kinds.contains("3D") && kinds.contains("Plot"), "{kinds:?}");
    // Block heights (handblocks' y is up), modes and latency, from the world and the frames.
    assert!(
        topics.contains("/world") && topics.contains("/frame"),
        "{topics:?}"
    );
    let paths: Vec<&str> = configs
        .values()
        .flat_map(|c| c["paths"].as_array().into_iter().flatten())
        .filter_map(|p| p["value"].as_str())
        .collect();
    assert!(
        paths.contains(&"/world.blocks[0].pose.position[1]"),
        "{paths:?}"
    );
    assert!(paths.contains(&"/world.blocks[0].mode"), "{paths:?}");
}

/// The checker itself refuses what Foxglove would not find: a field misspelt, an index into a
/// single value, a path ending on a message, a topic we do not serve.
#[test]
fn the_path_check_refuses_what_is_not_in_the_schema() {
    let refused = |path: &'static str| std::panic::catch_unwind(|| check_path(path, true)).is_err();
    assert!(!refused("/world.blocks[3].pose.position[2]"));
    assert!(!refused("/frame.render_ns.@div(1000000)"));
    assert!(!refused("/hand.wrist.rotation[3]"));
    for bad in [
        "/world.blocks[0].pose.positon[1]",
        "/world.blocks[0].pose.position[3]",
        "/world.blocks[0].pose",
        "/world.blocks.mode",
        "/world.step[0]",
        "/frame.render_ms",
        "/latency.histograms",
        "/scene.entities",
        "/world.step.@frobnicate",
    ] {
        assert!(refused(bad), "{bad} was let through");
    }
}
