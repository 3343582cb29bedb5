//! Window mode: a winit window whose surface shows the output (side by side, or the anaglyph;
//! separate mode shows side by side). The session's loop keeps its own pacing and pumps the
//! window's events between frames (`pump_app_events` with a zero timeout), so the window never
//! blocks the frame loop.

use std::sync::Arc;
use std::time::{Duration, Instant};

use common::config::scene::Scene;
use winit::application::ApplicationHandler;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::platform::pump_events::{EventLoopExtPumpEvents, PumpStatus};
use winit::platform::x11::EventLoopBuilderExtX11;
use winit::window::{Window, WindowId};

use crate::error::RenderError;
use crate::pipeline::{composite_bind_group, composite_pipeline, CompositeUniform};
use crate::renderer::{instance_descriptor, request_adapter, Presenter, Renderer};
use crate::settings::{OutputMode, RenderSettings};

/// What to tell a user with no display: what is missing and how to render anyway.
pub const NO_DISPLAY_HELP: &str = "set [renderer] mode = \"headless\" in the session file to \
    render offscreen (frames as PNG with --frames-dir DIR)";

/// Checks the environment for a display before touching any windowing library: this build
/// speaks X11 (XWayland serves Wayland desktops), so it needs `DISPLAY`.
pub fn check_display(display: Option<&str>, wayland: Option<&str>) -> Result<(), RenderError> {
    if display.is_some_and(|d| !d.is_empty()) {
        return Ok(());
    }
    let why = if wayland.is_some_and(|w| !w.is_empty()) {
        "window mode needs an X11 display (DISPLAY is not set; this build draws Wayland \
         desktops through XWayland, which sets DISPLAY)"
    } else {
        "window mode needs a display: neither DISPLAY nor WAYLAND_DISPLAY is set"
    };
    Err(RenderError::Window(format!("{why}; {NO_DISPLAY_HELP}")))
}

#[derive(Default)]
struct App {
    title: String,
    size: (u32, u32),
    window: Option<Arc<Window>>,
    error: Option<String>,
    closed: bool,
    resized: Option<(u32, u32)>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_some() || self.error.is_some() {
            return;
        }
        let attrs = Window::default_attributes()
            .with_title(self.title.clone())
            .with_inner_size(winit::dpi::PhysicalSize::new(self.size.0, self.size.1));
        match el.create_window(attrs) {
            Ok(w) => self.window = Some(Arc::new(w)),
            Err(e) => self.error = Some(e.to_string()),
        }
    }

    fn window_event(&mut self, _el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => self.closed = true,
            WindowEvent::Resized(s) => self.resized = Some((s.width, s.height)),
            _ => {}
        }
    }
}

/// The open window: pump it once per frame.
pub struct WindowHandle {
    event_loop: EventLoop<()>,
    app: App,
}

/// What the window did since the last pump.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowStatus {
    Open,
    /// The user closed it.
    Closed,
}

impl WindowHandle {
    /// Handles pending window events without waiting; applies a resize to the surface.
    pub fn pump(&mut self, renderer: &mut Renderer) -> WindowStatus {
        let status = self
            .event_loop
            .pump_app_events(Some(Duration::ZERO), &mut self.app);
        if let Some((w, h)) = self.app.resized.take() {
            renderer.resize_surface(w, h);
        }
        if self.app.closed || matches!(status, PumpStatus::Exit(_)) {
            WindowStatus::Closed
        } else {
            WindowStatus::Open
        }
    }
}

impl Renderer {
    /// A renderer that shows its frames in a new window (and can still read them back).
    pub fn new_window(
        settings: &RenderSettings,
        scene: &Scene,
    ) -> Result<(Renderer, WindowHandle), RenderError> {
        check_display(
            std::env::var("DISPLAY").ok().as_deref(),
            std::env::var("WAYLAND_DISPLAY").ok().as_deref(),
        )?;
        settings.validate().map_err(RenderError::Settings)?;
        let window_err = |e: &dyn std::fmt::Display| {
            RenderError::Window(format!(
                "the window could not be opened: {e}; {NO_DISPLAY_HELP}"
            ))
        };
        // The renderer's loop may run on any thread; X11 does not mind.
        let mut event_loop = EventLoop::builder()
            .with_any_thread(true)
            .build()
            .map_err(|e| window_err(&e))?;
        let (w, h) = match settings.output {
            OutputMode::Anaglyph => (settings.width, settings.height),
            _ => (2 * settings.width, settings.height),
        };
        let mut app = App {
            title: format!("handblocks ({})", settings.output.name()),
            size: (w, h),
            ..App::default()
        };
        let deadline = Instant::now() + Duration::from_secs(5);
        while app.window.is_none() && app.error.is_none() && Instant::now() < deadline {
            event_loop.pump_app_events(Some(Duration::from_millis(10)), &mut app);
        }
        let window = match (app.window.clone(), app.error.take()) {
            (Some(w), _) => w,
            (None, Some(e)) => return Err(window_err(&e)),
            (None, None) => return Err(window_err(&"no window after 5 s")),
        };
        let instance = wgpu::Instance::new(instance_descriptor());
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| window_err(&e))?;
        let (adapter, device, queue) = request_adapter(&instance, Some(&surface))?;
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| window_err(&"the GPU cannot present to this window"))?;
        // Our loop paces itself at the session's frame rate; don't also wait for vblank.
        config.present_mode = wgpu::PresentMode::AutoNoVsync;
        let mut renderer = Renderer::with_device(settings, scene, &adapter, device, queue)?;
        surface.configure(&renderer.device, &config);
        let composite = composite_pipeline(&renderer.device, renderer.module(), config.format);
        let (bind_group, uniform) = composite_bind_group(
            &renderer.device,
            &composite,
            renderer.eyes_view(),
            &composite_uniform(settings, config.width, config.height),
        );
        renderer.presenter = Some(Presenter {
            surface,
            config,
            composite,
            bind_group,
            uniform,
        });
        Ok((renderer, WindowHandle { event_loop, app }))
    }

    /// The window changed size: the surface follows (the eyes keep their size; the output
    /// pass scales them).
    pub fn resize_surface(&mut self, width: u32, height: u32) {
        let settings = self.settings().clone();
        let Some(p) = &mut self.presenter else { return };
        if width == 0 || height == 0 {
            return; // minimised
        }
        p.config.width = width;
        p.config.height = height;
        p.surface.configure(&self.device, &p.config);
        let u = composite_uniform(&settings, width, height);
        self.write_composite_uniform(&u);
    }
}

fn composite_uniform(s: &RenderSettings, dst_w: u32, dst_h: u32) -> CompositeUniform {
    let mode = match s.output {
        OutputMode::Anaglyph => 1,
        _ => 0,
    };
    CompositeUniform {
        mode: [mode, s.width, s.height, 0],
        dst: [dst_w as f32, dst_h as f32, 0.0, 0.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_display_is_a_clear_error_naming_the_fallback() {
        let e = check_display(None, None).unwrap_err().to_string();
        assert!(e.contains("neither DISPLAY nor WAYLAND_DISPLAY"), "{e}");
        assert!(e.contains("mode = \"headless\""), "{e}");
        let e = check_display(Some(""), Some("wayland-0"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("XWayland"), "{e}");
        assert!(check_display(Some(":0"), None).is_ok());
    }
}
