//! `verdant serve`.

use anyhow::{Result, bail};

use super::args::resolve_world;
use super::out::say;

pub(crate) fn serve(world: &str, addr: &str) -> Result<()> {
    let dir = resolve_world(world)?;
    if verdant::stream::http::is_url(world) {
        bail!("verdant serve serves a world folder, not {world}");
    }
    let server = verdant::tools::serve::WorldServer::start(&dir, addr)?;
    say!("serving {} at {}", dir.display(), server.url())?;
    server.wait();
    Ok(())
}
