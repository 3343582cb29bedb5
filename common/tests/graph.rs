//! The process graph declared once (issue 29): a stage opens only the ports the topic table
//! grants it, and a session's stages follow from the stage table and its settings.

use std::path::Path;

use common::bus::{Bus, BusConfig, BusError, PayloadKind};
use common::config::Session;
use common::topic::{Role, SliceTopicSpec, TopicLayout, TopicSpec, TopicVisitor};
use common::{topics, Stage, Topic};

/// A stage's node refuses a port its topic's row does not name it for, and says so; a
/// free-named node (a tool, a test) is not restricted.
#[test]
fn a_stage_may_open_only_the_ports_the_topic_table_grants_it() {
    let config = BusConfig::for_session(&format!("graph{}", std::process::id())).unwrap();
    {
        let launcher = Bus::open(&config, "launcher").unwrap();
        let _services = launcher.create_services().unwrap();
        let stepper = Bus::for_stage(&config, Stage::Stepper).unwrap();
        assert!(stepper.inlet::<topics::Hand>().is_ok());
        assert!(stepper.slice_outlet::<topics::World>().is_ok());
        let refused = stepper
            .outlet::<topics::Glove>()
            .err()
            .expect("not granted");
        let message = refused.to_string();
        assert!(
            message.contains("does not name the stepper stage a publisher of `glove`"),
            "{message}"
        );
        let refused = stepper.inlet::<topics::Frame>().err().expect("not granted");
        assert!(
            refused.to_string().contains("a reader of `frame`"),
            "{refused}"
        );
        // Every port each topic's row names is granted to its stage.
        struct OpenAll<'c>(&'c BusConfig, usize);
        impl OpenAll<'_> {
            /// An inlet for each reader of `P`'s row; the outlets are the caller's (a fixed-size
            /// and a slice topic's outlets have constructors of their own).
            fn readers<P: TopicLayout>(&mut self) -> Result<(), BusError>
            where
                P::Payload: PayloadKind,
            {
                for stage in P::TOPIC.readers() {
                    drop(Bus::for_stage(self.0, *stage)?.inlet::<P>()?);
                    self.1 += 1;
                }
                Ok(())
            }
        }
        impl TopicVisitor for OpenAll<'_> {
            type Error = BusError;
            fn visit<P: TopicSpec>(&mut self) -> Result<(), BusError> {
                for stage in P::TOPIC.publishers() {
                    drop(Bus::for_stage(self.0, *stage)?.outlet::<P>()?);
                    self.1 += 1;
                }
                self.readers::<P>()
            }
            fn visit_slice<P: SliceTopicSpec>(&mut self) -> Result<(), BusError> {
                for stage in P::TOPIC.publishers() {
                    drop(Bus::for_stage(self.0, *stage)?.slice_outlet::<P>()?);
                    self.1 += 1;
                }
                self.readers::<P>()
            }
        }
        let mut all = OpenAll(&config, 0);
        Topic::visit_each(&mut all).unwrap();
        assert!(all.1 > 20, "{} ports", all.1);
        let tool = Bus::open(&config, "a-tool").unwrap();
        assert!(tool.outlet::<topics::Glove>().is_ok());
    }
    config.remove_resources().unwrap();
}

/// Each shipped session's graph: one source, readers in table (pipeline) order but for a
/// bridge that publishes (after the stepper), nothing twice.
#[test]
fn every_session_runs_its_source_and_the_readers_its_settings_call_for() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/sessions");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let session = Session::load(&path).unwrap();
        let graph = session.graph();
        seen += 1;
        assert_ne!(graph.source.role(), Role::Reader, "{}", path.display());
        assert!(!graph.readers.contains(&graph.source), "{}", path.display());
        for s in &graph.readers {
            assert_ne!(s.role(), Role::Source, "{}", path.display());
        }
        let mut sorted = graph.readers.clone();
        sorted.dedup();
        assert_eq!(sorted.len(), graph.readers.len(), "{}", path.display());
        assert_eq!(
            graph.readers.contains(&Stage::Recorder),
            session.recorder.file.is_some(),
            "{}",
            path.display()
        );
    }
    assert!(seen >= 5);
    let live = Session::load(&dir.join("live.toml")).unwrap().graph();
    assert_eq!(live.source, Stage::Acquisition);
    assert_eq!(
        live.readers,
        [Stage::Kinematics, Stage::Stepper, Stage::Renderer]
    );
    assert_eq!(live.source_outputs, [Topic::Glove, Topic::Tracker]);
    let viewer = Session::load(&dir.join("remote-viewer.toml"))
        .unwrap()
        .graph();
    assert_eq!(viewer.source, Stage::Bridge);
    assert_eq!(viewer.readers, [Stage::Renderer, Stage::Recorder]);
}
