//! `deog copy`: what one store holds, into another (`deog-server`'s
//! `copy_store` does the work).

use crate::store_location::StoreLocation;
use anyhow::{Result, bail};
use clap::Args;
use deog_harness::Progress;
use deog_server::Store;
use deog_server::store::{CopyProgress, copy_store};

/// Options of `deog copy`.
#[derive(Debug, Args)]
pub struct CopyArgs {
    /// The store to copy from: a map server's data directory (the server
    /// must not be running on it) or a PostgreSQL URL,
    /// `postgres://USER@HOST/DB` (servers may keep running on it).
    #[arg(long)]
    pub from: String,
    /// The store to copy into: a data directory, created if missing, or a
    /// PostgreSQL URL (the schema is created if missing). What it holds
    /// already stays; a map of the same name is completed.
    #[arg(long)]
    pub to: String,
    /// Copy only this map (repeat for several); frames, pose estimates and
    /// rigs are copied whole either way.
    #[arg(long = "map")]
    pub maps: Vec<String>,
}

/// Runs the copy.
pub fn run(args: CopyArgs) -> Result<()> {
    let from = StoreLocation::parse(&args.from)?;
    let to = StoreLocation::parse(&args.to)?;
    if let StoreLocation::Directory(path) = &from {
        if !path.is_dir() {
            bail!("--from {}: no such data directory", path.display());
        }
        // Opening creates a store: a folder that holds none must stay as it is.
        if !path.join("db").is_file() {
            bail!(
                "--from {}: not a map server's data directory (it holds no store)",
                path.display()
            );
        }
    }
    let same = match (&from, &to) {
        (StoreLocation::Directory(a), StoreLocation::Directory(b)) => {
            b.exists() && matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
        }
        (StoreLocation::Postgres(a), StoreLocation::Postgres(b)) => a == b,
        _ => false,
    };
    if same {
        bail!("--from and --to name the same store, {}", from.describe());
    }
    let source = open(&from, "--from")?;
    let destination = open(&to, "--to")?;
    let progress = Progress::new("copying tiles and frames", "items", 0);
    let report = copy_store(
        source.as_ref(),
        destination.as_ref(),
        &args.maps,
        &mut |step| match step {
            CopyProgress::Total(total) => progress.set_total(total),
            CopyProgress::Advanced(items) => progress.inc(items),
            CopyProgress::Step(line) => tracing::info!("{line}"),
        },
    )?;
    progress.finish();
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

fn open(location: &StoreLocation, flag: &str) -> Result<Box<dyn Store>> {
    Ok(match location {
        StoreLocation::Directory(path) => Box::new(StoreLocation::open_sled(path, 64, flag)?),
        StoreLocation::Postgres(url) => Box::new(StoreLocation::open_postgres(url, flag)?),
    })
}
