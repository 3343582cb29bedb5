//! The run-time inlet: a reader of a topic chosen at run time ([`Bus::any_inlet`]), for the
//! processes that read topics by name or by the dozen (the recorder, the bridge, `handblocks
//! echo`, Python) rather than by type. One variant per row of the topic table, generated from
//! it (`crate::topic::each_topic!`), so a topic added to the table needs no code here; each
//! sample received is a [`SampleView`] of the publisher's memory, fixed-size and slice topics
//! alike. A receive costs a match on the topic over the typed [`Inlet`]'s: no allocation, no
//! lock.

use super::*;
use crate::topic::{topics, SampleView};

/// The bytes of `value` (a sample, a header or a slice of elements).
///
/// # Safety
/// `T` must have no padding: every byte initialised. The topic table checks that of every
/// sample, header and element type at compile time (its field list covers every byte).
unsafe fn bytes_of<T: ?Sized>(value: &T) -> &[u8] {
    std::slice::from_raw_parts(
        (value as *const T).cast::<u8>(),
        std::mem::size_of_val(value),
    )
}

/// A received sample of topic `P` as a [`SampleView`].
fn view_of<P: TopicLayout>(sample: &Received<P>) -> SampleView<'_>
where
    P::Payload: PayloadKind,
{
    let payload = P::Payload::payload(sample);
    let header = sample.user_header();
    // SAFETY: every payload and header type of the table is one its field list covers
    // (checked at compile time, `topic::fields`), so all its bytes are initialised.
    let (sample, elements) = unsafe {
        match P::TOPIC.element_size() {
            None => (bytes_of(payload), &[][..]),
            Some(_) => (bytes_of(header), bytes_of(payload)),
        }
    };
    // The lengths are the topic's: the port's types are the topic's marker's.
    SampleView::of_port(P::TOPIC, sample, elements)
}

/// The run-time inlet and its sample, a variant per topic of the table.
macro_rules! any_ports {
    ($($topic:ident)*) => {
        /// An inlet of a topic chosen at run time ([`Bus::any_inlet`]): an [`Inlet`] of the
        /// topic's marker type, whichever it is. It counts what it receives and the gaps as
        /// any inlet does, and the bus grants it only to a stage the topic's row names a
        /// reader ([`Bus::for_stage`]).
        pub enum AnyInlet {
            $(
                #[doc = concat!("An inlet of `topics::", stringify!($topic), "`.")]
                $topic(Inlet<topics::$topic>),
            )*
        }

        /// A sample an [`AnyInlet`] received, held in the publisher's memory until it is
        /// dropped (as a typed [`Received`] is).
        pub enum AnySample {
            $(
                #[doc = concat!("A sample of `topics::", stringify!($topic), "`.")]
                $topic(Received<topics::$topic>),
            )*
        }

        impl AnyInlet {
            fn open(bus: &Bus, topic: Topic) -> Result<AnyInlet, BusError> {
                Ok(match topic {
                    $(Topic::$topic => AnyInlet::$topic(bus.inlet::<topics::$topic>()?),)*
                })
            }

            /// The next unread sample, zero-copy, or None ([`Inlet::receive`]).
            pub fn receive(&self) -> Result<Option<AnySample>, BusError> {
                Ok(match self {
                    $(AnyInlet::$topic(i) => i.receive()?.map(AnySample::$topic),)*
                })
            }

            pub fn topic(&self) -> Topic {
                match self {
                    $(AnyInlet::$topic(_) => Topic::$topic,)*
                }
            }

            /// Samples received so far.
            pub fn received(&self) -> u64 {
                match self {
                    $(AnyInlet::$topic(i) => i.received(),)*
                }
            }

            /// This inlet's counter for the latency report.
            pub fn counter(&self) -> TopicCounter {
                match self {
                    $(AnyInlet::$topic(i) => i.counter(),)*
                }
            }

            /// Sleeps until a sample may have arrived, or `timeout` passes ([`Inlet::wait`]).
            pub fn wait(&self, timeout: Duration) -> Result<(), BusError> {
                match self {
                    $(AnyInlet::$topic(i) => i.wait(timeout),)*
                }
            }

            fn wakeable(&self) -> &dyn Wakeable {
                match self {
                    $(AnyInlet::$topic(i) => i,)*
                }
            }
        }

        impl AnySample {
            pub fn topic(&self) -> Topic {
                match self {
                    $(AnySample::$topic(_) => Topic::$topic,)*
                }
            }

            /// The sample's stamp, in the publisher's memory.
            pub fn stamp(&self) -> &Stamp {
                match self {
                    $(AnySample::$topic(s) => <topics::$topic as TopicLayout>::stamp(
                        s.payload(),
                        s.user_header(),
                    ),)*
                }
            }

            /// The sample's bytes, read in place: by its topic's field list, or written out
            /// whole as a recording's message.
            pub fn view(&self) -> SampleView<'_> {
                match self {
                    $(AnySample::$topic(s) => view_of::<topics::$topic>(s),)*
                }
            }
        }
    };
}

crate::topic::each_topic!(any_ports);

impl Wakeable for AnyInlet {
    fn wake_source(&self) -> WakeSource<'_> {
        self.wakeable().wake_source()
    }
    fn has_samples(&self) -> bool {
        self.wakeable().has_samples()
    }
}

impl Bus {
    /// A subscriber on `topic`, chosen at run time, with its listener: an [`Inlet`] of the
    /// topic's marker type as [`Bus::inlet`] opens it (a stage may open it only where the
    /// topic's row names it a reader), whose samples are received as [`SampleView`]s.
    pub fn any_inlet(&self, topic: Topic) -> Result<AnyInlet, BusError> {
        AnyInlet::open(self, topic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::{BlockState, HandSample, WorldHeader};

    /// A topic named at run time is read as its typed inlet reads it: the same bytes, the
    /// same stamp, counted the same; a world's elements follow its header.
    #[test]
    fn a_topic_chosen_at_run_time_reads_its_samples_as_bytes() {
        let config = BusConfig::for_session(&format!("anyin{}", std::process::id())).unwrap();
        let bus = Bus::open(&config, "test").unwrap();
        let _services = bus.create_services().unwrap();
        let hands = bus.any_inlet(Topic::Hand).unwrap();
        let worlds = bus.any_inlet(Topic::World).unwrap();
        assert_eq!((hands.topic(), worlds.topic()), (Topic::Hand, Topic::World));
        let mut hand_out = bus.outlet::<topics::Hand>().unwrap();
        let mut world_out = bus.slice_outlet::<topics::World>().unwrap();
        let hand = HandSample {
            finger_count: 3,
            ..HandSample::default()
        };
        let sent = hand_out.publish(&hand).unwrap();
        let header = WorldHeader {
            block_count: 2,
            ..WorldHeader::default()
        };
        let mut block = BlockState::default();
        block.pose.position = [1.0, 2.0, 3.0];
        world_out.publish_copy(&header, &[block, block]).unwrap();

        let s = hands.receive().unwrap().expect("a hand");
        assert_eq!(s.topic(), Topic::Hand);
        assert_eq!(*s.stamp(), sent);
        let v = s.view();
        assert_eq!((v.topic(), v.len(), v.stamp()), (Topic::Hand, 0, sent));
        assert_eq!(v.sample().len(), std::mem::size_of::<HandSample>());
        let mut expected = hand;
        *expected.stamp_mut() = sent;
        // SAFETY: HandSample is plain old data without padding.
        let bytes = unsafe { bytes_of(&expected) };
        assert_eq!(v.sample(), bytes);
        assert!(v.elements().is_empty());
        drop(s);
        assert_eq!((hands.received(), hands.counter().count), (1, 1));

        let s = worlds.receive().unwrap().expect("a world");
        let v = s.view();
        assert_eq!(v.len(), 2);
        assert_eq!(v.sample().len(), std::mem::size_of::<WorldHeader>());
        assert_eq!(v.elements().len(), 2 * std::mem::size_of::<BlockState>());
        assert_eq!(&v.elements()[..8], &1.0f64.to_le_bytes());
        assert!(worlds.receive().unwrap().is_none());
        drop((s, hands, worlds, hand_out, world_out, _services, bus));
        config.remove_resources().unwrap();
    }

    /// The bus's port accounting holds for the run-time inlet: a stage opens one only on a
    /// topic whose row names it a reader.
    #[test]
    fn a_stage_opens_a_run_time_inlet_only_where_it_reads() {
        let config = BusConfig::for_session(&format!("anygr{}", std::process::id())).unwrap();
        let bus = Bus::for_stage(&config, Stage::Recorder).unwrap();
        assert!(bus.any_inlet(Topic::World).is_ok());
        let refused = bus.any_inlet(Topic::Latency).err().expect("refused");
        assert!(refused.to_string().contains("reader"), "{refused}");
        drop(bus);
        config.remove_resources().unwrap();
    }
}
