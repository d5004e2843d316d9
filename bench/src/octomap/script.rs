//! OctoMap's side: `bench/octomap_insert.py` (built into this crate, so the
//! bench runs from any directory) as a child process of the chosen
//! interpreter, reading the scans file and writing the final map's cells.

use std::ffi::OsString;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result, bail};

use crate::python_script::{PythonScript, failure};
use serde::Deserialize;

use super::cell_list::{ExportedCell, read_cells};

/// The script, as kept in the repository.
const SCRIPT: &str = include_str!("../../octomap_insert.py");

/// How to install what the script needs.
pub(crate) const INSTALL_HINT: &str = "pip install octomap-python numpy";

/// The versions the script reports.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct Versions {
    /// The interpreter's.
    pub python: String,
    /// numpy's.
    pub numpy: String,
    /// The octomap-python distribution's (it bundles OctoMap itself).
    pub octomap: String,
}

/// The script's report of a run.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct ScriptReport {
    /// The versions it ran with.
    #[serde(flatten)]
    pub versions: Versions,
    /// Scans inserted, all passes (scans without echoes count, as on
    /// deog's side, though they insert nothing).
    pub scans: u64,
    /// Seconds of insertion, all passes.
    pub seconds: f64,
    /// Seconds of each pass.
    pub pass_seconds: Vec<f64>,
    /// Leaves of the final tree (`getNumLeafNodes`): the API does not count
    /// the nodes an insertion updates.
    pub leaf_cells: u64,
    /// Nodes of the final tree, inner ones included.
    pub tree_nodes: u64,
    /// The tree's memory as OctoMap reckons it (`memoryUsage`), bytes.
    pub memory_bytes: u64,
}

/// OctoMap's run: its report and its final map's cells.
#[derive(Debug, Clone)]
pub(crate) struct OctomapRun {
    /// What the script printed.
    pub report: ScriptReport,
    /// The final map's z = 0 layer.
    pub cells: Vec<ExportedCell>,
}

/// What the OctoMap run needs beyond the scans.
#[derive(Debug, Clone)]
pub(crate) struct OctomapSettings {
    /// Metres per voxel.
    pub resolution: f64,
    /// OctoMap's `prob_hit`.
    pub prob_hit: f64,
    /// OctoMap's `prob_miss`.
    pub prob_miss: f64,
    /// Clamping, as probabilities (lower, upper).
    pub clamp: (f64, f64),
    /// `insertPointCloud`'s `maxrange`, metres.
    pub max_range: f64,
    /// Times the whole log is inserted.
    pub passes: u32,
}

/// The interpreter `python` with the script written into `work`.
pub(crate) struct OctomapScript(PythonScript);

impl OctomapScript {
    /// Writes the script into `work` (a temporary directory) for `python`.
    pub fn new(python: impl Into<OsString>, work: &Path) -> Result<Self> {
        PythonScript::new(
            python,
            work,
            "octomap_insert.py",
            SCRIPT,
            "OctoMap's side",
            INSTALL_HINT,
        )
        .map(Self)
    }

    /// The versions, or why the script cannot run: no such interpreter, or
    /// a module it needs missing (the reason then says how to install it).
    pub fn probe(&self) -> Result<Versions, String> {
        self.0.probe()
    }

    /// Inserts the scans of `scans_file` as `settings` say; the final map's
    /// cells go through `cells_file`.
    pub fn run(
        &self,
        scans_file: &Path,
        cells_file: &Path,
        settings: &OctomapSettings,
    ) -> Result<OctomapRun> {
        let output = self
            .command()
            .arg(scans_file)
            .arg("--cells-out")
            .arg(cells_file)
            .args([
                "--resolution",
                &settings.resolution.to_string(),
                "--prob-hit",
                &settings.prob_hit.to_string(),
                "--prob-miss",
                &settings.prob_miss.to_string(),
                "--clamp-min",
                &settings.clamp.0.to_string(),
                "--clamp-max",
                &settings.clamp.1.to_string(),
                "--max-range",
                &settings.max_range.to_string(),
                "--passes",
                &settings.passes.to_string(),
            ])
            .output()
            .with_context(|| format!("running {}", self.0.python()))?;
        if !output.status.success() {
            bail!("{}", failure("OctoMap's insertion", &output));
        }
        let report: ScriptReport = serde_json::from_slice(&output.stdout).with_context(|| {
            format!(
                "reading the script's report: {}",
                String::from_utf8_lossy(&output.stdout).trim()
            )
        })?;
        let file = File::open(cells_file)
            .with_context(|| format!("opening OctoMap's cells, {}", cells_file.display()))?;
        let cells = read_cells(BufReader::new(file))
            .with_context(|| format!("reading OctoMap's cells, {}", cells_file.display()))?;
        Ok(OctomapRun { report, cells })
    }

    fn command(&self) -> Command {
        self.0.command()
    }
}
