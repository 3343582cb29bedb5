//! With no Vulkan driver at all, the renderer says what to install instead of panicking.
//! Its own test binary: it hides the drivers from the Vulkan loader for the whole process.

use std::path::PathBuf;

use common::config::scene::{Effects, Scene, WorldSettings};
use renderer::{RenderError, RenderSettings, Renderer};

#[test]
fn no_adapter_is_a_clear_error_naming_the_package() {
    // The Vulkan loader reads only these manifests: none exists, so no driver loads.
    std::env::set_var("VK_ICD_FILENAMES", "/nonexistent/handblocks-no-driver.json");
    std::env::set_var("VK_DRIVER_FILES", "/nonexistent/handblocks-no-driver.json");
    let scene = Scene {
        file: PathBuf::from("test.toml"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: vec![],
        hand: None,
        left_hand: None,
    };
    match Renderer::new_headless(&RenderSettings::default(), &scene) {
        Err(e @ RenderError::NoAdapter(_)) => {
            let text = e.to_string();
            println!("{text}");
            assert!(text.starts_with("no GPU adapter"), "{text}");
            assert!(
                text.contains("apt-get install mesa-vulkan-drivers libvulkan1"),
                "{text}"
            );
        }
        Err(e) => panic!("expected NoAdapter, got {e}"),
        Ok(r) => panic!("found an adapter without drivers: {}", r.adapter_name()),
    }
}
