//! The page and its scripts, served from the binary: written for this project, nothing fetched
//! at run time but the socket, so a headset on a network without the internet works.

/// `GET /` (with the session's token).
pub const INDEX_HTML: &str = include_str!("../page/index.html");
/// `GET /app.js`: the page's script, a module (no secret in it; the token is in the page's
/// URL).
pub const APP_JS: &str = include_str!("../page/app.js");
/// `GET /gl.js`: the module `app.js` imports, its matrices, meshes and orbit camera (our own
/// code, kept apart from the page's protocol and drawing).
pub const GL_JS: &str = include_str!("../page/gl.js");
