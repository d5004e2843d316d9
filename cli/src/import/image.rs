//! `deog import --map M FILE`: a ROS map_server map becomes a map's cells.

use std::path::Path;

use anyhow::{Context, Result, bail};
use deog_grid::{ClampLimits, Resolution, TileSize};
use deog_harness::Progress;
use deog_mapfile::MapImage;
use deog_mapping::{ImportTarget, image_origin_cell, import_map};
use deog_proto::v1 as pb;
use deog_robot_client::UpdateSenderConfig;

use super::{ImportArgs, connect};

/// Imports the map_server map whose YAML is `file` into map `name`: its
/// known pixels become the map's cells.
pub fn import(args: &ImportArgs, name: &str, file: &Path) -> Result<()> {
    let path = file;
    let file = path.display().to_string();
    let image = MapImage::load(path)?;
    // Everything about the image alone is checked before the map is
    // created, so a bad file leaves the server as it was.
    let resolution = Resolution::new(image.resolution)
        .with_context(|| format!("{file}: resolution {} m", image.resolution))?;
    image_origin_cell(&image, resolution).with_context(|| format!("{file} cannot be imported"))?;
    let client_id = client_id(path);

    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (import, acks) = runtime.block_on(async {
        let client = connect(args).await?;
        let info = client
            .ensure_map(pb::CreateMapRequest {
                name: name.to_string(),
                resolution_m: image.resolution,
                // The server's defaults: tile size 64, clamp limits 0.12 and 0.97.
                ..pb::CreateMapRequest::default()
            })
            .await
            .with_context(|| format!("creating map {name:?}"))?;
        if (info.resolution_m - image.resolution).abs()
            > deog_mapping::map_import::RESOLUTION_TOLERANCE * info.resolution_m
        {
            bail!(
                "map {name:?} exists with cells of {} m, but {file} has pixels of {} m: import it into a new map",
                info.resolution_m,
                image.resolution
            );
        }
        if info.tile_count > 0 && !args.force {
            bail!(
                "map {name:?} already holds {} observed cells; importing {file} would add its evidence to theirs. \
                 Import into a new map, clear this one first, or pass --force to add anyway",
                info.cell_count
            );
        }
        let target = ImportTarget {
            resolution: Resolution::new(info.resolution_m).context("the map's resolution_m")?,
            tile_size: TileSize::new(info.tile_size).context("the map's tile_size")?,
            limits: ClampLimits::from_probabilities(
                info.clamp_min_probability,
                info.clamp_max_probability,
            )
            .context("the map's clamp limits")?,
        };
        let import = import_map(&image, &target)
            .with_context(|| format!("{file} cannot be imported into map {name:?}"))?;
        let mut sender = client
            .updates(name, &client_id, UpdateSenderConfig::default())
            .await
            .with_context(|| format!("opening an update stream to map {name:?}"))?;
        let progress = Progress::new("importing tiles", "tiles", import.deltas.len() as u64);
        for delta in &import.deltas {
            sender.push(delta.clone()).await?;
            progress.inc(1);
        }
        let acks = sender
            .close()
            .await
            .with_context(|| format!("writing the cells of {file} to map {name:?}"))?;
        progress.finish();
        anyhow::Ok((import, acks))
    })?;
    println!(
        "{file}: {} x {} pixels, {} occupied and {} free cells written to map {name} in {} tiles ({} unknown pixels left unobserved); map version {}",
        image.width,
        image.height,
        import.occupied,
        import.free,
        import.deltas.len(),
        import.unknown,
        acks.map_version
    );
    Ok(())
}

/// The update client id of an import: `import/<file stem>`, with every
/// character the server does not take in a client id replaced by `_` and
/// the whole kept to its 128 characters. The same file imported again
/// continues the same client's sequence.
fn client_id(file: &Path) -> String {
    let stem = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut id: String = "import/"
        .chars()
        .chain(stem.chars().map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-') {
                c
            } else {
                '_'
            }
        }))
        .take(128)
        .collect();
    if id.len() == "import/".len() {
        id.push_str("map");
    }
    id
}
