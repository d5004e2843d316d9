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
    /// `insertPointCloud` calls, all passes (the scans with points).
    #[serde(default)]
    pub calls: u64,
    /// Seconds of the same calls with no points, when asked for
    /// ([`OctomapSettings::time_empty_calls`]): what the calls cost beyond
    /// OctoMap's work on the rays.
    #[serde(default)]
    pub empty_call_seconds: Option<f64>,
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
    /// Times every scan is inserted (the whole log, for laser-mapping).
    pub passes: u32,
    /// Also time the same calls with no points
    /// ([`ScriptReport::empty_call_seconds`]).
    pub time_empty_calls: bool,
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
            .args(settings.time_empty_calls.then_some("--time-empty-calls"))
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

#[cfg(test)]
mod tests {
    use std::collections::HashMap;
    use std::io::BufWriter;

    use approx::assert_abs_diff_eq;

    use super::*;
    use crate::octomap::point_cloud::{ScanCloud, write_clouds};

    /// Runs the real script when `python3` has octomap and numpy; says so
    /// and passes when it has not (the bench then reports deog alone too).
    #[test]
    fn the_script_updates_each_scans_ray_cells_once_and_exports_them() {
        let work = tempfile::tempdir().expect("a temporary directory");
        let script = OctomapScript::new("python3", work.path()).expect("the script");
        if let Err(reason) = script.probe() {
            deog_harness::eprintln_above_bars!("skipped: OctoMap's side cannot run here: {reason}");
            return;
        }
        let scan = |origin: [f64; 2], points: Vec<[f64; 2]>| ScanCloud { origin, points };
        // Points at cell centres, 5 cm cells: cell (i, j) is centred at
        // (0.05 i + 0.025, 0.05 j + 0.025).
        let scans = [
            // Along +x from cell (0, 0) to an echo in cell (10, 0).
            scan([0.025, 0.025], vec![[0.525, 0.025]]),
            // Nothing to insert: counted as a scan, not as a call.
            scan([3.0, 3.0], vec![]),
            // Past the 1 m range: cells (0..20, 20) freed, no echo.
            scan([0.025, 1.025], vec![[10.025, 1.025]]),
            // Along +y from cell (5, -5) to an echo in cell (5, 0), which
            // the first ray freed: each scan updates it once.
            scan([0.275, -0.225], vec![[0.275, 0.025]]),
        ];
        let scans_file = work.path().join("scans.bin");
        let cells_file = work.path().join("cells.bin");
        let file = File::create(&scans_file).expect("create");
        write_clouds(BufWriter::new(file), &scans).expect("write");
        let settings = OctomapSettings {
            resolution: 0.05,
            prob_hit: 0.7,
            prob_miss: 0.4,
            clamp: (0.12, 0.97),
            max_range: 1.0,
            passes: 1,
            time_empty_calls: true,
        };
        let run = script
            .run(&scans_file, &cells_file, &settings)
            .expect("the script runs");
        assert_eq!((run.report.scans, run.report.calls), (4, 3));
        assert!(run.report.empty_call_seconds.is_some_and(|s| s >= 0.0));

        let (hit, miss) = (0.847_298, -0.405_465);
        let mut want: HashMap<(i32, i32), f64> = HashMap::new();
        for x in 0..10 {
            want.insert((x, 0), miss);
        }
        want.insert((10, 0), hit);
        for x in 0..20 {
            want.insert((x, 20), miss);
        }
        for y in -5..0 {
            want.insert((5, y), miss);
        }
        want.insert((5, 0), miss + hit);
        let got: HashMap<(i32, i32), f64> = run
            .cells
            .iter()
            .map(|c| ((c.x, c.y), f64::from(c.log_odds)))
            .collect();
        assert_eq!(got.len(), run.cells.len(), "no cell twice");
        let mut keys: Vec<_> = got.keys().copied().collect();
        keys.sort_unstable();
        let mut want_keys: Vec<_> = want.keys().copied().collect();
        want_keys.sort_unstable();
        assert_eq!(keys, want_keys);
        for (cell, log_odds) in &want {
            assert_abs_diff_eq!(got[cell], *log_odds, epsilon = 1e-4);
        }
    }
}
