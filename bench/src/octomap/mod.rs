//! OctoMap as a peer, shared by the benches that run it
//! (`deog bench laser-mapping`, `deog bench sonar-mapping`):
//! `bench/octomap_insert.py` run as a child Python process, and the two
//! files it reads and writes.
//!
//! Its parts: `point_cloud` (the scans file the script reads: per scan a
//! sensor origin and world-frame points), `script` (the script as a child
//! process: probe, insert, export) and `cell_list` (the cells file it
//! writes back: the final map's z = 0 layer with OctoMap's log-odds).

pub(crate) mod cell_list;
pub(crate) mod point_cloud;
mod script;

pub(crate) use script::{OctomapRun, OctomapScript, OctomapSettings, Versions};
