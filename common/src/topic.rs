//! The topic table: every topic of a session declared once, with its sample type, its service
//! sizing and the stages (`crate::stage`) that publish and read it.
//!
//! Everything else that depends on the set of topics derives from the table instead of
//! listing topics again: the bus's typed ports ([`crate::bus::Bus::outlet`] and
//! [`crate::bus::Bus::inlet`] take a marker type from [`topics`], so a port's sample type is
//! its topic's and a wrong pairing does not compile), the services the launcher creates, the
//! subscribers it waits for before starting the source ([`Topic::readers`]; the bridge, a
//! reader of every topic in the table, counted on those its session names), the
//! source's topics ([`Stage::recorded_outputs`]), the recording's channels
//! ([`Topic::RECORDED`]: the topics the recorder reads), each sample's field list
//! ([`Topic::schema`]: the recording's schema, what `handblocks echo` prints, Python's arrays)
//! and the run-time inlet (the bus's `AnyInlet`, generated per topic through `each_topic!`:
//! a reader of a topic named at run time, which receives its samples as [`SampleView`]s).

use crate::samples::*;
pub use crate::stage::{Role, Stage, WakesBy};
use crate::stamp::{Stamp, Stamped};

pub mod fields;
mod view;

use fields::{meaning, message_type, message_types};
pub use fields::{Base, Elements, Field, FieldValue, Meaning, Message, Scalar, Schema};
pub use view::SampleView;

/// Any topic at the type level, fixed-size or slice: a marker type of [`topics`] names its
/// [`Topic`] and how one of its samples lies in shared memory, as iceoryx2's ports see it (a
/// payload, which may be a slice, and a user header). The bus's [`crate::bus::Inlet`] and
/// [`crate::bus::Outlet`] are generic over it, as iceoryx2's `Publisher<S, Payload: ?Sized,
/// UserHeader>` is, so one port type serves both kinds; what differs (how a sample is written)
/// is in [`TopicSpec`] and [`SliceTopicSpec`]. Only the table declares topics (sealed).
pub trait TopicLayout: sealed::Sealed + 'static {
    /// iceoryx2's payload: the sample of a fixed-size topic, the elements of a slice topic.
    type Payload: ?Sized + std::fmt::Debug + iceoryx2::prelude::IceoryxSend + 'static;
    /// iceoryx2's user header: `()` for a fixed-size topic, the header of a slice topic.
    type Header: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + 'static;
    /// The topic's runtime name, for service names, counters and messages.
    const TOPIC: Topic;
    /// A sample's stamp: in the payload of a fixed-size topic, in the header of a slice one.
    fn stamp<'s>(payload: &'s Self::Payload, header: &'s Self::Header) -> &'s Stamp;
}

/// A fixed-size topic: each sample is one value of `Sample`, carried as iceoryx2's payload,
/// ports typed by the marker cannot carry another topic's samples.
pub trait TopicSpec: TopicLayout<Payload = Self::Sample, Header = ()> {
    /// What every sample of the topic is (its counts checked where outside bytes become one).
    type Sample: Stamped + crate::samples::Counted;
}

mod sealed {
    pub trait Sealed {}
}

/// A topic whose samples are a fixed header and a slice of elements whose length the
/// publisher chooses (the `world` topic: a [`WorldHeader`] and one [`BlockState`] per block of
/// the scene). On the bus the header is iceoryx2's user header and the elements its slice
/// payload, so a sample is sized from the scene and still read in place.
pub trait SliceTopicSpec:
    TopicLayout<Payload = [Self::Element], Header: Stamped + Default + crate::samples::Counted>
{
    /// One element of the slice.
    type Element: Copy + std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + 'static;
}

/// Something done once per topic of the table with the topic's types in hand (creating its
/// service, opening a port of the right sample type), since a loop over [`Topic::ALL`] knows
/// only the runtime value. [`Topic::visit_each`] calls [`TopicVisitor::visit`] (or
/// [`TopicVisitor::visit_slice`] for a slice topic) in table order.
pub trait TopicVisitor {
    type Error;
    fn visit<P: TopicSpec>(&mut self) -> Result<(), Self::Error>;
    fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), Self::Error>;
}

/// The marker's trait impl and visit call of one row: a fixed-size sample, or a header and a
/// slice of elements (`World: WorldHeader[BlockState]`).
macro_rules! topic_kind {
    (spec $topic:ident, $sample:ident) => {
        impl TopicLayout for $topic {
            type Payload = $sample;
            type Header = ();
            const TOPIC: Topic = Topic::$topic;
            fn stamp<'s>(payload: &'s $sample, _: &'s ()) -> &'s Stamp {
                payload.stamp()
            }
        }
        impl TopicSpec for $topic {
            type Sample = $sample;
        }
    };
    (spec $topic:ident, $sample:ident, $elem:ident) => {
        impl TopicLayout for $topic {
            type Payload = [$elem];
            type Header = $sample;
            const TOPIC: Topic = Topic::$topic;
            fn stamp<'s>(_: &'s [$elem], header: &'s $sample) -> &'s Stamp {
                header.stamp()
            }
        }
        impl SliceTopicSpec for $topic {
            type Element = $elem;
        }
    };
    (visit $v:ident, $topic:ident) => {
        $v.visit::<topics::$topic>()?
    };
    (visit $v:ident, $topic:ident, $elem:ident) => {
        $v.visit_slice::<topics::$topic>()?
    };
    (element $elem:ident) => {
        Some(std::mem::size_of::<$elem>())
    };
    (element) => {
        None
    };
    (elements $name:ident $elem:ident) => {
        Some(fields::Elements {
            name: stringify!($name),
            schema: <$elem as fields::Message>::SCHEMA,
        })
    };
    (elements) => {
        None
    };
}

/// True when `stage` is one of `stages` (a `const` `contains`).
const fn contains(stages: &[Stage], stage: Stage) -> bool {
    let mut i = 0;
    while i < stages.len() {
        if stages[i] as u32 == stage as u32 {
            return true;
        }
        i += 1;
    }
    false
}

/// Declares the [`Topic`] enum, its per-topic facts, the marker types of [`topics`] and their
/// [`TopicSpec`], the [`Stamped`] access and the field list ([`Message`]) of each sample type,
/// and [`each_topic`], from one row per topic.
macro_rules! topic_table {
    (
        $(#[$enum_doc:meta])*
        pub enum Topic {
            $(
                $(#[$doc:meta])*
                $topic:ident: $sample:ident $([$elements:ident: $elem:ident])? {
                    name: $name:literal,
                    buffer: $buffer:expr,
                    max_publishers: $max_publishers:expr,
                    publishers: [$($publisher:ident),* $(,)?],
                    readers: [$($reader:ident),* $(,)?],
                    fields: [$($field:ident $(($($meaning:tt)*))?),* $(,)?] $(,)?
                }
            ),* $(,)?
        }
    ) => {
        $(#[$enum_doc])*
        #[repr(u32)]
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Topic {
            $($(#[$doc])* $topic,)*
        }

        impl Topic {
            /// Every topic, in table order (`Topic as usize` indexes it).
            pub const ALL: [Topic; [$(Topic::$topic),*].len()] = [$(Topic::$topic),*];

            /// The service name; the session's own iceoryx2 prefix keeps sessions apart.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Topic::$topic => $name,)*
                }
            }

            /// The topic's name outside the bus, ROS style (`/world`): the channel of a
            /// recording and of the live Foxglove view, the same string in both so that a
            /// layout made on one works on the other.
            pub const fn channel(self) -> &'static str {
                match self {
                    $(Topic::$topic => concat!("/", $name),)*
                }
            }

            /// The topic a channel name (`/world`, or a bare `world` as recordings before the
            /// names were shared had it) names.
            pub fn from_channel(channel: &str) -> Option<Topic> {
                let name = channel.strip_prefix('/').unwrap_or(channel);
                Topic::ALL.into_iter().find(|t| t.name() == name)
            }

            /// Samples a subscriber may hold unread before the oldest is overwritten.
            pub const fn subscriber_buffer(self) -> usize {
                match self {
                    $(Topic::$topic => $buffer,)*
                }
            }

            /// Publishers the service admits (fixed when it is created).
            pub const fn max_publishers(self) -> usize {
                match self {
                    $(Topic::$topic => $max_publishers,)*
                }
            }

            /// The stages that publish this topic.
            pub const fn publishers(self) -> &'static [Stage] {
                match self {
                    $(Topic::$topic => &[$(Stage::$publisher),*],)*
                }
            }

            /// The stages that read this topic.
            pub const fn readers(self) -> &'static [Stage] {
                match self {
                    $(Topic::$topic => &[$(Stage::$reader),*],)*
                }
            }

            /// The schema (message type) name of the topic's samples in a recording,
            /// `handblocks/msg/` and the topic's name and `Sample` (`WorldSample`).
            pub const fn schema_name(self) -> &'static str {
                match self {
                    $(Topic::$topic => concat!("handblocks/msg/", stringify!($topic), "Sample"),)*
                }
            }

            /// The byte size of the topic's sample type; of a slice topic, its header's.
            pub const fn sample_size(self) -> usize {
                match self {
                    $(Topic::$topic => std::mem::size_of::<$sample>(),)*
                }
            }

            /// The byte size of one element of a slice topic; None for a fixed-size one.
            pub const fn element_size(self) -> Option<usize> {
                match self {
                    $(Topic::$topic => topic_kind!(element $($elem)?),)*
                }
            }

            /// Calls `visitor` once per topic, in table order, with the topic's marker type.
            pub fn visit_each<V: TopicVisitor>(visitor: &mut V) -> Result<(), V::Error> {
                $(topic_kind!(visit visitor, $topic $(, $elem)?);)*
                Ok(())
            }

            /// The topic's field list: its sample type's (of a slice topic, its header's,
            /// with the elements' as [`Schema::elements`]), named [`Topic::schema_name`].
            pub const fn schema(self) -> &'static Schema {
                match self {
                    $(Topic::$topic => <$sample as Message>::SCHEMA,)*
                }
            }
        }

        /// Calls macro `m` with the name of every topic of the table, in table order
        /// (`m! { Glove Tracker ... }`), so that a layer above this one generates code per
        /// topic from the table without naming a topic: the bus's run-time inlet, `AnyInlet`,
        /// a variant per topic.
        macro_rules! each_topic {
            ($m:ident) => {
                $m! { $($topic)* }
            };
        }
        pub(crate) use each_topic;

        // Each sample type's field list; a slice topic's names its elements.
        $(
            message_type!(
                $sample,
                concat!("handblocks/msg/", stringify!($topic), "Sample"),
                topic_kind!(elements $($elements $elem)?),
                [$($field $(($($meaning)*))?),*]
            );
        )*

        /// The marker type of each topic, for the bus's typed ports: `bus.outlet::<topics::Hand>()`
        /// is an outlet of `HandSample`s on `hand`; `bus.slice_outlet::<topics::World>()` one
        /// of world headers with up to the bus's slice capacity of block states each. The types have no values.
        pub mod topics {
            use super::*;
            $(
                $(#[$doc])*
                #[derive(Debug)]
                pub enum $topic {}

                impl sealed::Sealed for $topic {}

                topic_kind!(spec $topic, $sample $(, $elem)?);
            )*
        }

        // Every sample starts with its stamp. Each topic has a sample type of its own (a
        // recording tells the topics apart by their schema), so one impl per row.
        $(
            impl Stamped for $sample {
                fn stamp(&self) -> &crate::stamp::Stamp {
                    &self.stamp
                }
                fn stamp_mut(&mut self) -> &mut crate::stamp::Stamp {
                    &mut self.stamp
                }
            }
        )*
    };
}

topic_table! {
    /// Every publish-subscribe service of a session, one row of the table each. Each is paired
    /// with an event service of the same name, so consumers sleep until a sample arrives
    /// instead of spinning.
    ///
    /// Subscriber buffers are sized for a second of a 1 kHz source, so a stage that is
    /// descheduled for a while loses nothing; the renderer drains everything and keeps only
    /// the newest world state, so its frames need less.
    ///
    /// To add a topic: (1) its sample type in `samples.rs` (`#[repr(C)]`, starting with its
    /// `stamp`); (2) its row here, with the sample's fields in memory order (`fields`: a field
    /// may say what its numbers mean, `(flag)`, `(length)`, `(names LIST)`; a type nested in
    /// it is declared once below, `message_types!`). Then the stages in its row open their
    /// ports, `bus.outlet::<topics::New>()` / `bus.inlet::<topics::New>()`; the services, the
    /// launcher's wait for readers, the recording's channels and schema, the recorder's and
    /// the bridge's inlets, `handblocks echo` and Python's arrays follow from the row. A row
    /// `Name: Header[elements: Element]` is a slice topic (a header and a run of elements
    /// whose length the publisher picks, sized from the scene): its outlet is
    /// `bus.slice_outlet` (its inlet `bus.inlet`, as any) and the recording writes it with
    /// `write_slice`.
    pub enum Topic {
        /// Finger joint angles from the data glove (or the scripted hand, or a replay).
        Glove: GloveSample {
            name: "glove",
            buffer: 1024,
            max_publishers: 4,
            publishers: [Acquisition, Replay, Bridge, Null],
            readers: [Kinematics, Recorder, Bridge],
            fields: [stamp, sensor_count, side, angles],
        },
        /// The wrist pose from the 6-DoF tracker.
        Tracker: TrackerSample {
            name: "tracker",
            buffer: 1024,
            max_publishers: 4,
            publishers: [Acquisition, Replay, Bridge, Null],
            readers: [Kinematics, Recorder, Bridge],
            fields: [stamp, station, side, wrist],
        },
        /// Whole-hand joint poses (an OpenXR hand): replayed from a recording or a CARL file,
        /// or a headset's hand tracking (WebXR).
        Joints: JointsSample {
            name: "joints",
            buffer: 1024,
            max_publishers: 4,
            publishers: [Replay, Bridge, Webxr, External],
            readers: [Kinematics, Recorder, Bridge],
            fields: [stamp, tracked (flag), side, wrist, joints],
        },
        /// The hand model: finger check points and the palm, as the stepper reads them (a
        /// replay publishes it only from a shared world host's recording, which holds hands
        /// and no source samples).
        Hand: HandSample {
            name: "hand",
            buffer: 1024,
            max_publishers: 3,
            publishers: [Kinematics, Bridge, Replay],
            readers: [Stepper, Renderer, Recorder, Bridge],
            fields: [
                stamp,
                wrist,
                tracked (flag),
                finger_count,
                finger_point_count,
                palm_vertex_count,
                finger_points,
                finger_radius,
                palm_vertices,
                side,
                participant,
            ],
        },
        /// The blocks' states after each step (the replay reads it to pace itself): a header
        /// and one block state per block of the scene.
        World: WorldHeader[blocks: BlockState] {
            name: "world",
            buffer: 1024,
            max_publishers: 2,
            publishers: [Stepper, Bridge],
            readers: [Renderer, Replay, Recorder, Bridge, Webxr],
            fields: [
                stamp,
                step,
                hand_seq,
                block_count (length),
                grasped_block,
                finger_count,
                finger_point_count,
                finger_points,
            ],
        },
        /// One drawn frame's timing.
        Frame: FrameSample {
            name: "frame",
            buffer: 256,
            max_publishers: 2,
            publishers: [Renderer, Bridge],
            readers: [Recorder, Bridge],
            fields: [stamp, world_seq, render_ns, origin_to_photon_ns, skipped_worlds],
        },
        /// Each stage's latency report, about once a second; the launcher (no stage) reads
        /// them, and a recording does not keep them (they go into the session report).
        Latency: LatencySample {
            name: "latency",
            buffer: 32,
            max_publishers: 10,
            publishers: [Acquisition, Replay, Kinematics, Stepper, Renderer, Recorder, Bridge, Webxr, External, Null],
            readers: [],
            fields: [
                stamp,
                stage,
                final_report,
                silence_ns,
                first_output_ns,
                last_output_ns,
                counters,
                devices,
                histograms,
            ],
        },
        /// Another participant's hand in a shared world (docs/sessions.md "Shared sessions"):
        /// a participant's bridge publishes the others' hands the host sent it, for its
        /// renderer, its headset's page (the webxr stage) and its recorder (the host's own bus has every participant's on `hand`).
        PeerHand: PeerHandSample {
            name: "peer_hand",
            buffer: 256,
            max_publishers: 1,
            publishers: [Bridge],
            readers: [Renderer, Recorder, Bridge, Webxr],
            fields: [stamp, own_participant, _reserved, hand],
        },
    }
}

/// The block modes' names, by the value a `mode` holds ([`BlockMode::name`]).
const BLOCK_MODE_NAMES: [&str; BlockMode::ALL.len()] = {
    let mut names = [""; BlockMode::ALL.len()];
    let mut i = 0;
    while i < names.len() {
        // Names by value: the modes are numbered 0, 1, ... in ALL's order.
        assert!(BlockMode::ALL[i] as usize == i);
        names[i] = BlockMode::ALL[i].name();
        i += 1;
    }
    names
};

message_types! {
    Stamp: "handblocks/Stamp" [seq, source_time_ns, origin_ns, publish_ns],
    Pose: "handblocks/Pose" [position, rotation],
    BlockState: "handblocks/BlockState" [pose, mode (names BLOCK_MODE_NAMES), held_by],
    TopicCounter: "handblocks/TopicCounter" [topic, role, count, gaps, last_seq],
    DeviceCounters: "handblocks/DeviceCounters" [
        device,
        _reserved,
        samples,
        garbage_bytes,
        rejected_records,
        other_station_records,
        link_losses,
        reconnects,
        device_errors,
    ],
    EncodedHistogram: "handblocks/EncodedHistogram" [len, _reserved, bytes],
}

impl Topic {
    pub fn from_u32(v: u32) -> Option<Topic> {
        Topic::ALL.get(v as usize).copied()
    }

    /// True when the recorder reads this topic: a recording has a channel for it.
    pub const fn is_recorded(self) -> bool {
        contains(self.readers(), Stage::Recorder)
    }

    /// The topics a recording holds, in table order: those the recorder reads.
    pub const RECORDED: [Topic; Topic::recorded_count()] = {
        let mut out = [Topic::ALL[0]; Topic::recorded_count()];
        let (mut i, mut n) = (0, 0);
        while i < Topic::ALL.len() {
            if Topic::ALL[i].is_recorded() {
                out[n] = Topic::ALL[i];
                n += 1;
            }
            i += 1;
        }
        out
    };

    const fn recorded_count() -> usize {
        let (mut i, mut n) = (0, 0);
        while i < Topic::ALL.len() {
            if Topic::ALL[i].is_recorded() {
                n += 1;
            }
            i += 1;
        }
        n
    }

    /// How many of `stages` read this topic: the subscribers it has once they all attached.
    pub fn readers_among(self, stages: &[Stage]) -> usize {
        self.readers().iter().filter(|s| stages.contains(s)).count()
    }
}

impl Stage {
    /// The topics this stage publishes that a recording keeps, in table order: for a source,
    /// its samples (what the launcher waits for before the session's time starts, and what a
    /// replay plays back from a recording); its latency report is not one of them.
    pub fn recorded_outputs(self) -> impl Iterator<Item = Topic> {
        Topic::RECORDED
            .into_iter()
            .filter(move |t| t.publishers().contains(&self))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The discriminants are the table's order, which `from_u32` and every
    /// `[_; Topic::ALL.len()]` indexed by `Topic as usize` rely on.
    #[test]
    fn topics_are_numbered_in_table_order() {
        for (i, t) in Topic::ALL.into_iter().enumerate() {
            assert_eq!(t as usize, i);
            assert_eq!(Topic::from_u32(i as u32), Some(t));
        }
        assert_eq!(Topic::from_u32(Topic::ALL.len() as u32), None);
    }

    /// What the table says, as the rest of the project used to spell it out topic by topic.
    #[test]
    fn the_table_derives_what_was_listed_by_hand() {
        assert_eq!(
            Topic::RECORDED,
            [
                Topic::Glove,
                Topic::Tracker,
                Topic::Joints,
                Topic::Hand,
                Topic::World,
                Topic::Frame,
                Topic::PeerHand,
            ]
        );
        let outputs = |s: Stage| s.recorded_outputs().collect::<Vec<_>>();
        assert_eq!(
            outputs(Stage::Replay),
            [Topic::Glove, Topic::Tracker, Topic::Joints, Topic::Hand]
        );
        assert_eq!(outputs(Stage::Acquisition), [Topic::Glove, Topic::Tracker]);
        assert_eq!(Topic::Hand.schema_name(), "handblocks/msg/HandSample");
        assert_eq!(Topic::World.schema_name(), "handblocks/msg/WorldSample");
        assert_eq!(
            Topic::PeerHand.schema_name(),
            "handblocks/msg/PeerHandSample"
        );
        assert_eq!(Topic::Hand.element_size(), None);
        assert_eq!(
            Topic::World.element_size(),
            Some(std::mem::size_of::<BlockState>())
        );
        assert_eq!(
            Topic::Latency.sample_size(),
            std::mem::size_of::<LatencySample>()
        );
        let all_readers = [
            Stage::Kinematics,
            Stage::Stepper,
            Stage::Renderer,
            Stage::Recorder,
        ];
        assert_eq!(Topic::Hand.readers_among(&all_readers), 3);
        assert_eq!(Topic::World.readers_among(&all_readers[..2]), 0);
        // Every stage reports its latency.
        assert_eq!(Topic::Latency.publishers(), Stage::ALL);
        for t in Topic::ALL {
            assert!(t.publishers().len() <= t.max_publishers(), "{t:?}");
        }
    }

    /// Each marker type names its own topic, and visiting goes through the table in order.
    #[test]
    fn markers_name_their_topics() {
        struct Names(Vec<(Topic, usize)>);
        impl TopicVisitor for Names {
            type Error = ();
            fn visit<P: TopicSpec>(&mut self) -> Result<(), ()> {
                self.0.push((P::TOPIC, std::mem::size_of::<P::Sample>()));
                Ok(())
            }
            fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), ()> {
                self.0.push((P::TOPIC, std::mem::size_of::<P::Header>()));
                Ok(())
            }
        }
        let mut names = Names(Vec::new());
        Topic::visit_each(&mut names).unwrap();
        let expected: Vec<_> = Topic::ALL.iter().map(|t| (*t, t.sample_size())).collect();
        assert_eq!(names.0, expected);
        assert_eq!(<topics::Glove as TopicLayout>::TOPIC, Topic::Glove);
    }
}
