//! `--rig NAME|FILE`: which sensor rig a process's robots carry or its
//! frames come from.

use anyhow::{Context, Result};
use deog_rig::{Rig, load_rig_spec};
use deog_robot_client::MapClient;

/// Loads the rig `spec` names (a built-in name or a rig file).
pub fn load_rig(spec: &str) -> Result<Rig> {
    load_rig_spec(spec).context("--rig")
}

/// Stores `rig` on the map server (a no-op for a built-in rig or one
/// stored before), so that consumers of the frames read them with it.
pub async fn publish_rig(client: &MapClient, rig: &Rig) -> Result<()> {
    if deog_rig::is_built_in(rig.name()) {
        return Ok(());
    }
    client
        .put_rig(rig)
        .await
        .with_context(|| format!("storing rig {} on the map server", rig.name()))
}
