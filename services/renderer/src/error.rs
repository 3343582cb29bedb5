//! The renderer's one error type, in its own module: the drawing core, the PNG and frame
//! writers and the preview all return it, and none of them should depend on another for it.

/// Why rendering could not start or go on.
#[derive(Debug)]
pub enum RenderError {
    /// No Vulkan adapter (no GPU driver, no Mesa software driver).
    NoAdapter(String),
    Device(String),
    /// Settings out of range, or a block shape that cannot be drawn.
    Settings(String),
    /// The window could not be opened (no display).
    Window(String),
    Gpu(String),
    Io(String),
    /// The session's bus (the renderer process).
    Bus(common::bus::BusError),
}

impl std::fmt::Display for RenderError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RenderError::NoAdapter(e) => write!(
                f,
                "no GPU adapter ({e}): install a Vulkan driver, or Mesa's software one \
                 (Debian/Ubuntu: apt-get install mesa-vulkan-drivers libvulkan1)"
            ),
            RenderError::Device(e) => write!(f, "the GPU device could not be opened: {e}"),
            RenderError::Settings(e) => write!(f, "renderer settings: {e}"),
            RenderError::Window(e) => write!(f, "{e}"),
            RenderError::Gpu(e) => write!(f, "GPU error: {e}"),
            RenderError::Io(e) => write!(f, "{e}"),
            RenderError::Bus(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for RenderError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            RenderError::Bus(e) => Some(e),
            _ => None,
        }
    }
}

impl From<common::bus::BusError> for RenderError {
    fn from(e: common::bus::BusError) -> RenderError {
        RenderError::Bus(e)
    }
}
