//! `mss init`: writes a commented template scene.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;

use crate::GlobalArgs;

/// Arguments of `mss init`.
#[derive(Debug, Clone, Args)]
pub struct InitArgs {
    /// Scene file to write.
    #[arg(value_name = "FILE", default_value = "scene.toml")]
    pub file: PathBuf,
    /// Overwrite FILE if it exists.
    #[arg(long)]
    pub force: bool,
}

/// Writes the template scene (every key, with units and defaults, commented).
pub fn run(args: &InitArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    let path = &args.file;
    if path.is_dir() {
        bail!(
            "{} is a folder; give the name of the scene file to write",
            path.display()
        );
    }
    if path.exists() && !args.force {
        bail!(
            "{} already exists; choose another name or add --force to overwrite it",
            path.display()
        );
    }
    mss_scene::mss_io::atomic::write_atomic(path, |w| {
        w.write_all(mss_scene::scene::TEMPLATE_SCENE_TOML.as_bytes())
    })
    .with_context(|| format!("cannot write the template scene {}", path.display()))?;
    if global.chatty() {
        crate::outln!(
            "wrote {}: edit it, then `mss check {0}` and `mss run {0}`",
            path.display()
        );
    }
    Ok(())
}
