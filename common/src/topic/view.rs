//! A sample of any topic as the bytes it is: what a reader of a topic chosen at run time
//! holds (the bus's `AnyInlet` gives one per sample received, in the publisher's memory; a
//! recording one per message). Read by the topic's field list ([`Topic::schema`]), or written
//! out whole (a recording's message, the bridge's).

use std::mem::size_of;

use super::fields::Schema;
use super::Topic;
use crate::stamp::Stamp;

/// One sample of `topic`, borrowed: the sample's bytes (of a slice topic, its header's) and
/// the bytes of its elements (empty for a fixed-size topic). Nothing is copied.
#[derive(Debug, Clone, Copy)]
pub struct SampleView<'s> {
    topic: Topic,
    sample: &'s [u8],
    elements: &'s [u8],
}

impl<'s> SampleView<'s> {
    /// A view of `sample` and `elements` as one sample of `topic`: None unless `sample` is as
    /// long as the topic's sample (or header) and `elements` holds whole elements (none for a
    /// fixed-size topic).
    pub fn new(topic: Topic, sample: &'s [u8], elements: &'s [u8]) -> Option<SampleView<'s>> {
        let whole = match topic.element_size() {
            None => elements.is_empty(),
            Some(size) => elements.len().is_multiple_of(size.max(1)),
        };
        (sample.len() == topic.sample_size() && whole).then_some(SampleView {
            topic,
            sample,
            elements,
        })
    }

    /// A sample a typed port of `topic` received: its bytes have the topic's sizes by the
    /// port's types, so they are not measured again per sample.
    pub(crate) fn of_port(topic: Topic, sample: &'s [u8], elements: &'s [u8]) -> SampleView<'s> {
        debug_assert!(SampleView::new(topic, sample, elements).is_some());
        SampleView {
            topic,
            sample,
            elements,
        }
    }

    pub fn topic(&self) -> Topic {
        self.topic
    }

    /// The topic's field list, by which the bytes are read.
    pub fn schema(&self) -> &'static Schema {
        self.topic.schema()
    }

    /// The sample's bytes; of a slice topic, its header's.
    pub fn sample(&self) -> &'s [u8] {
        self.sample
    }

    /// The bytes of a slice topic's elements, one after the other; empty for a fixed-size one.
    pub fn elements(&self) -> &'s [u8] {
        self.elements
    }

    /// How many elements the sample has (0 for a fixed-size topic).
    pub fn len(&self) -> usize {
        self.topic
            .element_size()
            .map_or(0, |size| self.elements.len() / size.max(1))
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The sample's stamp (every sample starts with it), copied out.
    pub fn stamp(&self) -> Stamp {
        self.sample
            .get(..size_of::<Stamp>())
            // SAFETY: four u64, any bit pattern valid, read unaligned from as many bytes.
            .map(|b| unsafe { std::ptr::read_unaligned(b.as_ptr() as *const Stamp) })
            .unwrap_or_default()
    }
}
