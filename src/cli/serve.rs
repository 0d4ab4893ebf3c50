//! `verdant serve`.

use anyhow::{Result, bail};

use super::args::resolve_world;
use super::out::say;

pub(crate) fn serve(world: &std::ffi::OsStr, addr: &str) -> Result<()> {
    if let Some(url) = world.to_str().filter(|w| verdant::stream::http::is_url(w)) {
        bail!(
            "verdant serve serves a world folder, not {}",
            super::terminal_safe(url)
        );
    }
    let dir = resolve_world(world)?;
    let server = verdant::tools::serve::WorldServer::start(&dir, addr)?;
    say!("serving {} at {}", dir.display(), server.url())?;
    server.wait();
    Ok(())
}
