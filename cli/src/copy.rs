//! `deog copy`: what one store holds, into another (`deog-server`'s
//! `copy_store` does the work).

use anyhow::{Result, bail};
use clap::Args;
use deog_server::store::copy_store;
use deog_server::{SledConfig, SledStore};
use std::path::{Path, PathBuf};

/// Options of `deog copy`.
#[derive(Debug, Args)]
pub struct CopyArgs {
    /// The store to copy from: a map server's data directory (the server
    /// must not be running on it).
    #[arg(long)]
    pub from: PathBuf,
    /// The store to copy into: a data directory, created if missing. What
    /// it holds already stays; a map of the same name is completed.
    #[arg(long)]
    pub to: PathBuf,
    /// Copy only this map (repeat for several); frames, pose estimates and
    /// rigs are copied whole either way.
    #[arg(long = "map")]
    pub maps: Vec<String>,
}

/// Runs the copy.
pub fn run(args: CopyArgs) -> Result<()> {
    if args.from.to_string_lossy().contains("://") || args.to.to_string_lossy().contains("://") {
        bail!("deog copy takes data directories; this build opens no store named by a URL");
    }
    if !args.from.is_dir() {
        bail!("--from {}: no such data directory", args.from.display());
    }
    // Opening creates a store: a folder that holds none must stay as it is.
    if !args.from.join("db").is_file() {
        bail!(
            "--from {}: not a map server's data directory (it holds no store)",
            args.from.display()
        );
    }
    if args.to.exists()
        && let (Ok(from), Ok(to)) = (args.from.canonicalize(), args.to.canonicalize())
        && from == to
    {
        bail!("--from and --to name the same store, {}", from.display());
    }
    let source = open(&args.from, "--from")?;
    let destination = open(&args.to, "--to")?;
    let report = copy_store(&source, &destination, &args.maps, &mut |line| {
        tracing::info!("{line}");
    })?;
    for map in &report.maps {
        println!(
            "map {}: {} tiles, version {}, checksum {:016x}: the same in both stores ({} tiles written)",
            map.name, map.tiles, map.version, map.checksum, map.tiles_written
        );
    }
    println!(
        "{} robots: {} frames written, {} pose estimates, {} rigs",
        report.robots, report.frames_written, report.poses, report.rigs
    );
    Ok(())
}

fn open(path: &Path, flag: &str) -> Result<SledStore> {
    SledStore::open(&SledConfig::new(path)).map_err(|error| {
        let text = error.to_string();
        if text.contains("could not acquire lock") {
            anyhow::anyhow!(
                "{flag} {}: the store is in use (is a deog server running on it? stop it first)",
                path.display()
            )
        } else {
            anyhow::anyhow!("{flag} {}: {text}", path.display())
        }
    })
}
