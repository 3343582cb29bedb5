//! Which processes a session runs, and in what order: the process graph ([`Stage`]'s table
//! beside the topic table) as this session's settings cut it. The launcher starts what this
//! says and nothing else.

use crate::config::session::{RenderMode, Source};
use crate::config::Session;
use crate::topic::{Role, Stage, Topic};

/// A session's processes: its source and its readers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Graph {
    /// Where the session's samples start: acquisition, a replay, or (remote-fed) the bridge.
    pub source: Stage,
    /// The topics the source publishes, which the launcher waits for before time starts.
    pub source_outputs: Vec<Topic>,
    /// The readers, in pipeline order: started before the source (the last first) and
    /// stopped after it in this order, so each drains what its upstream sent.
    pub readers: Vec<Stage>,
}

impl Session {
    /// The stages this session runs ([`Graph`]).
    pub fn graph(&self) -> Graph {
        // A remote-fed session (a viewer) has no pipeline of its own: the bridge is its source.
        let remote_fed = matches!(self.source, Source::Remote);
        // A shared world's host takes its hands from the participants (the bridge is its
        // source, and they arrive as hands: no kinematics); a participant takes the host's
        // world (no stepper of its own).
        let shared_host = matches!(self.source, Source::Shared);
        let shared_join = self.bridge.shared.as_ref().is_some_and(|s| !s.is_host());
        // The stage whose row in the stage table names this `[source] kind`
        // ([`Stage::selected_by`]); a session's kind is always one of them (the table test).
        let source = Stage::ALL
            .into_iter()
            .find(|s| s.selected_by().contains(&self.source.kind()))
            .unwrap_or(Stage::Acquisition);
        let source_outputs = if remote_fed || shared_host {
            self.bridge.outputs()
        } else {
            source.recorded_outputs().collect()
        };
        let bridge_publishes = self.bridge.is_on() && !self.bridge.outputs().is_empty();
        let runs = |stage: Stage| match stage {
            Stage::Kinematics => !remote_fed && !shared_host,
            Stage::Stepper => !remote_fed && !shared_join,
            Stage::Renderer => self.renderer.mode != RenderMode::Off,
            // Only when recording: a reader of every topic costs a wake-up per sample on
            // cores the pipeline needs, and a session pays only for what it asks for.
            Stage::Recorder => self.recorder.file.is_some(),
            Stage::Bridge => self.bridge.is_on() && !remote_fed,
            // A source runs only as the session's source (the filter below).
            _ => false,
        };
        let mut readers: Vec<Stage> = Stage::ALL
            .into_iter()
            .filter(|s| s.role() != Role::Source && *s != source && runs(*s))
            .collect();
        // A bridge that takes topics in from the other machine publishes them here: it stops
        // before their readers (the renderer, the recorder), or what it publishes after they
        // drained is lost (a frame taken in after the recorder stopped counted as dropped). It
        // still stops after the stepper, whose hand and world it drains to send them. One that
        // only reads stops last.
        if bridge_publishes {
            if let Some(at) = readers.iter().position(|s| *s == Stage::Bridge) {
                readers.remove(at);
                let after = readers
                    .iter()
                    .position(|s| *s == Stage::Stepper)
                    .map_or(0, |i| i + 1);
                readers.insert(after, Stage::Bridge);
            }
        }
        Graph {
            source,
            source_outputs,
            readers,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each `[source] kind` starts exactly one stage, the one whose row names it.
    #[test]
    fn every_source_kind_selects_one_stage() {
        for kind in Source::KINDS {
            let rows: Vec<Stage> = Stage::ALL
                .into_iter()
                .filter(|s| s.selected_by().contains(&kind))
                .collect();
            assert_eq!(rows.len(), 1, "{kind}: {rows:?}");
        }
        for stage in Stage::ALL {
            for kind in stage.selected_by() {
                assert!(Source::KINDS.contains(kind), "{stage:?}: {kind}");
            }
        }
    }
}
