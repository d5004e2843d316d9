//! `deog export`: a map on the server to ROS map_server files (PGM + YAML)
//! and a PNG, the thesis's "pgm creator". Works while the map is still being
//! built: the server sends each tile whole, so the export is a consistent
//! copy of every tile, each as of the moment it was read.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::TileMap;
use deog_harness::Progress;
use deog_mapfile::{to_png_with_scale_bar, write_map};
use deog_mapping::export_map;
use deog_robot_client::{ClientError, MapClient};

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};

/// Options of `deog export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The map to export.
    #[arg(long, env = "DEOG_MAP")]
    pub map: String,
    /// Folder to write into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// File name stem: writes STEM.pgm, STEM.yaml and STEM.png. Defaults to
    /// the map's name.
    #[arg(long)]
    pub name: Option<String>,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// Runs the export.
pub fn run(args: ExportArgs) -> Result<()> {
    let stem = args.name.clone().unwrap_or_else(|| args.map.clone());
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let map = runtime.block_on(fetch(&args))?;
    if map.observed_count() == 0 {
        bail!(
            "map {:?} is empty: no cell has been observed yet, so there is nothing to export",
            args.map
        );
    }
    let export = export_map(&map).with_context(|| format!("exporting map {:?}", args.map))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let yaml = write_map(&args.out, &stem, &export.image)?;
    let png = args.out.join(format!("{stem}.png"));
    to_png_with_scale_bar(&png, &export.image)?;
    let (image, counts) = (&export.image, &export.counts);
    println!(
        "map {}: {} x {} pixels of {} m, origin ({}, {}): {} cells occupied, {} free, {} unknown ({} observed but uncertain); wrote {} with its .pgm and .png",
        args.map,
        image.width,
        image.height,
        image.resolution,
        image.origin.0,
        image.origin.1,
        counts.occupied,
        counts.free,
        counts.unknown(),
        counts.uncertain,
        yaml.display()
    );
    Ok(())
}

/// A client of the map server `connection` names, once it is known to
/// hold map `map`.
pub(crate) async fn open_map(
    connection: &ConnectionArgs,
    timeout: &ConnectTimeoutArgs,
    map: &str,
) -> Result<MapClient> {
    let client = MapClient::connect(timeout.apply(connection.client_config()?)?).await?;
    if let Err(ClientError::Status(status)) = client.map_info(map).await
        && status.code() == tonic::Code::NotFound
    {
        bail!(
            "no map named {map:?} on the map server at {}",
            connection.server
        )
    }
    Ok(client)
}

/// Every tile of the map, as a [`TileMap`] with the map's settings.
async fn fetch(args: &ExportArgs) -> Result<TileMap> {
    let client = open_map(&args.connection, &args.timeout, &args.map).await?;
    let progress = Progress::new("exporting tiles", "tiles", 0);
    let (_, map) = client
        .download_with_progress(&args.map, &mut |read, total| {
            progress.set_total(total);
            progress.set_done(read);
        })
        .await
        .with_context(|| format!("reading the tiles of map {:?}", args.map))?;
    progress.finish();
    Ok(map)
}
