//! What a running system is doing, from two samples of the map server:
//! the rows `deog status` prints. Plain data in, plain data out; the
//! gathering over gRPC is the caller's.
//!
//! Rates need two samples (`before`, `after`): a map's writes per second
//! is its version's change over the time between them, a robot's frame
//! rate its frame count's. Ages are wall-clock seconds since the sampler
//! saw the newest frame or estimate arrive, `None` when none arrived while
//! it watched. Lags are in the robots' own frame clock: the newest frame's
//! sequence and time minus those of the frame the estimate follows.
//!
//! # Layout
//! - this file: the samples, the rows and [`status_rows`];
//! - `table`: [`status_table`], the rows as aligned text.

use serde::Serialize;

mod table;

pub use table::status_table;

/// A box in metres, world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bounds {
    /// Metres.
    pub min_x: f64,
    /// Metres.
    pub min_y: f64,
    /// Metres.
    pub max_x: f64,
    /// Metres.
    pub max_y: f64,
}

/// One map as a sample saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct MapSample {
    /// The map's name.
    pub name: String,
    /// Cells ever observed.
    pub cells: u64,
    /// Stored tiles.
    pub tiles: u64,
    /// Box of the observed cells; `None` while the map is empty.
    pub bounds: Option<Bounds>,
    /// Incremented by every applied batch and every clear.
    pub version: u64,
    /// The clients that applied batches to it, with their highest applied
    /// sequence.
    pub writers: Vec<(String, u64)>,
}

/// One robot's frames as a sample saw them.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSample {
    /// The robot's name.
    pub name: String,
    /// Frames stored.
    pub frames: u64,
    /// Sequence of the newest stored frame.
    pub last_sequence: u64,
    /// Frame-clock time of the newest stored frame, seconds; `None` if it
    /// could not be read.
    pub last_frame_time_s: Option<f64>,
    /// Sampler clock (seconds) at which a frame of this robot last arrived
    /// while the sampler watched; `None` if none did.
    pub last_arrival_s: Option<f64>,
}

/// The newest estimate of one robot on one map, as a sample saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateSample {
    /// The robot estimated.
    pub robot: String,
    /// The map the estimate is on.
    pub map: String,
    /// Sequence of the frame the estimate follows.
    pub frame_sequence: u64,
    /// Frame-clock time of that frame, seconds.
    pub frame_time_s: f64,
    /// Whether the filter believes it has converged.
    pub converged: bool,
    /// 0 when observations fit the map, towards 1 when probably lost.
    pub lost_score: f64,
    /// Estimated position, metres, world frame.
    pub position: (f64, f64),
    /// The true position at that frame, when the frame carries it.
    pub true_position: Option<(f64, f64)>,
    /// Sampler clock (seconds) at which an estimate of this robot on this
    /// map last arrived while the sampler watched; `None` if none did.
    pub last_arrival_s: Option<f64>,
}

/// Everything one sample read, at one instant of the sampler's clock.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sample {
    /// Sampler clock, seconds (any origin, the same for every sample).
    pub at_s: f64,
    /// The maps.
    pub maps: Vec<MapSample>,
    /// The robots with frames.
    pub robots: Vec<RobotSample>,
    /// The newest estimate per robot and map.
    pub estimates: Vec<EstimateSample>,
}

/// The server row: where it is and what its health service says.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ServerRow {
    /// The address asked.
    pub address: String,
    /// `SERVING`, `NOT_SERVING`, or what else the health check answered.
    pub health: String,
}

/// A map row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapRow {
    /// The map's name.
    pub name: String,
    /// Cells ever observed.
    pub cells: u64,
    /// Stored tiles.
    pub tiles: u64,
    /// Box of observed cells, metres; `None` while empty.
    pub bounds: Option<Bounds>,
    /// The map's version at the second sample.
    pub version: u64,
    /// Version increments per second between the samples; `None` for a
    /// map the first sample did not see, or one cleared and rebuilt.
    pub writes_per_s: Option<f64>,
    /// Who writes to the map, by client id.
    pub writers: Vec<WriterRow>,
}

/// A client that writes to a map.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WriterRow {
    /// The client's id, e.g. `carto/scout-1`.
    pub client_id: String,
    /// Its highest applied batch sequence.
    pub last_sequence: u64,
    /// Its sequence's advance per second between the samples (batches per
    /// second when it numbers them one by one).
    pub batches_per_s: Option<f64>,
}

/// A robot row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotRow {
    /// The robot's name.
    pub name: String,
    /// Frames stored.
    pub frames: u64,
    /// Frames stored per second between the samples.
    pub frames_per_s: Option<f64>,
    /// Seconds since the newest frame arrived; `None` if none arrived
    /// while the sampler watched.
    pub last_frame_age_s: Option<f64>,
}

/// A localizer row: the newest estimate of one robot on one map.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LocalizerRow {
    /// The robot estimated.
    pub robot: String,
    /// The map it is localized on.
    pub map: String,
    /// Whether the filter believes it has converged.
    pub converged: bool,
    /// 0 when observations fit the map, towards 1 when probably lost.
    pub lost_score: f64,
    /// Seconds since the newest estimate arrived; `None` if none arrived
    /// while the sampler watched.
    pub last_estimate_age_s: Option<f64>,
    /// Frame-clock seconds from the estimate's frame to the robot's
    /// newest frame.
    pub lag_s: Option<f64>,
    /// Frames from the estimate's frame to the robot's newest frame.
    pub lag_frames: u64,
    /// Distance from the estimate to the true position, metres, when the
    /// frame carries the truth (simulated robots).
    pub error_m: Option<f64>,
}

/// What `deog status` prints for one pair of samples; its JSON keys are
/// stable.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Status {
    /// The map server.
    pub server: ServerRow,
    /// Its maps, by name.
    pub maps: Vec<MapRow>,
    /// Robots with frames, by name.
    pub robots: Vec<RobotRow>,
    /// Localizers, by robot then map.
    pub localizers: Vec<LocalizerRow>,
}

/// The rows for `after`, with rates over the time since `before`.
pub fn status_rows(server: ServerRow, before: &Sample, after: &Sample) -> Status {
    let elapsed_s = after.at_s - before.at_s;
    // A rate over no time, or a counter that went back (a map cleared
    // and written again, a server started on a fresh store), means nothing.
    let rate = |old: Option<u64>, new: u64| -> Option<f64> {
        let old = old?;
        (elapsed_s > 0.0 && new >= old).then(|| (new - old) as f64 / elapsed_s)
    };
    let age = |arrival: Option<f64>| arrival.map(|t| (after.at_s - t).max(0.0));

    let mut maps: Vec<MapRow> = after
        .maps
        .iter()
        .map(|map| {
            let old = before.maps.iter().find(|m| m.name == map.name);
            let mut writers: Vec<WriterRow> = map
                .writers
                .iter()
                .map(|(client_id, last_sequence)| {
                    let old_sequence = old.and_then(|m| {
                        m.writers
                            .iter()
                            .find(|(id, _)| id == client_id)
                            .map(|&(_, s)| s)
                    });
                    WriterRow {
                        client_id: client_id.clone(),
                        last_sequence: *last_sequence,
                        batches_per_s: rate(old_sequence, *last_sequence),
                    }
                })
                .collect();
            writers.sort_by(|a, b| a.client_id.cmp(&b.client_id));
            MapRow {
                name: map.name.clone(),
                cells: map.cells,
                tiles: map.tiles,
                bounds: map.bounds,
                version: map.version,
                writes_per_s: rate(old.map(|m| m.version), map.version),
                writers,
            }
        })
        .collect();
    maps.sort_by(|a, b| a.name.cmp(&b.name));

    let mut robots: Vec<RobotRow> = after
        .robots
        .iter()
        .map(|robot| {
            let old = before.robots.iter().find(|r| r.name == robot.name);
            RobotRow {
                name: robot.name.clone(),
                frames: robot.frames,
                frames_per_s: rate(old.map(|r| r.frames), robot.frames),
                last_frame_age_s: age(robot.last_arrival_s),
            }
        })
        .collect();
    robots.sort_by(|a, b| a.name.cmp(&b.name));

    let mut localizers: Vec<LocalizerRow> = after
        .estimates
        .iter()
        .map(|estimate| {
            let robot = after.robots.iter().find(|r| r.name == estimate.robot);
            let lag_frames = robot.map_or(0, |r| {
                r.last_sequence.saturating_sub(estimate.frame_sequence)
            });
            let lag_s = robot
                .and_then(|r| r.last_frame_time_s)
                .map(|t| (t - estimate.frame_time_s).max(0.0));
            let error_m = estimate.true_position.map(|(x, y)| {
                let (ex, ey) = estimate.position;
                (ex - x).hypot(ey - y)
            });
            LocalizerRow {
                robot: estimate.robot.clone(),
                map: estimate.map.clone(),
                converged: estimate.converged,
                lost_score: estimate.lost_score,
                last_estimate_age_s: age(estimate.last_arrival_s),
                lag_s,
                lag_frames,
                error_m,
            }
        })
        .collect();
    localizers.sort_by(|a, b| (&a.robot, &a.map).cmp(&(&b.robot, &b.map)));

    Status {
        server,
        maps,
        robots,
        localizers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn server() -> ServerRow {
        ServerRow {
            address: "127.0.0.1:1".into(),
            health: "SERVING".into(),
        }
    }

    fn map(name: &str, version: u64) -> MapSample {
        MapSample {
            name: name.into(),
            cells: 100,
            tiles: 2,
            bounds: None,
            version,
            writers: vec![("carto/r1".into(), version)],
        }
    }

    fn robot(name: &str, frames: u64, last_arrival_s: Option<f64>) -> RobotSample {
        RobotSample {
            name: name.into(),
            frames,
            last_sequence: frames,
            last_frame_time_s: Some(frames as f64 * 0.1),
            last_arrival_s,
        }
    }

    #[test]
    fn rates_are_the_change_over_the_interval() {
        let before = Sample {
            at_s: 10.0,
            maps: vec![map("a", 100), map("gone", 5)],
            robots: vec![robot("r1", 40, None)],
            estimates: Vec::new(),
        };
        let after = Sample {
            at_s: 12.0,
            maps: vec![map("b", 7), map("a", 130)],
            robots: vec![robot("r1", 60, Some(11.5)), robot("r0", 3, None)],
            estimates: Vec::new(),
        };
        let status = status_rows(server(), &before, &after);
        let names: Vec<&str> = status.maps.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["a", "b"]);
        assert_eq!(status.maps[0].writes_per_s, Some(15.0));
        assert_eq!(status.maps[1].writes_per_s, None, "new map: no rate yet");
        assert_eq!(
            status.maps[0].writers,
            [WriterRow {
                client_id: "carto/r1".into(),
                last_sequence: 130,
                batches_per_s: Some(15.0)
            }]
        );
        assert_eq!(status.robots[0].name, "r0");
        assert_eq!(status.robots[0].frames_per_s, None);
        assert_eq!(status.robots[0].last_frame_age_s, None);
        assert_eq!(status.robots[1].frames_per_s, Some(10.0));
        assert_eq!(status.robots[1].last_frame_age_s, Some(0.5));
    }

    #[test]
    fn a_counter_that_went_back_has_no_rate() {
        let before = Sample {
            at_s: 0.0,
            maps: vec![map("a", 100)],
            ..Sample::default()
        };
        let after = Sample {
            at_s: 1.0,
            maps: vec![map("a", 3)],
            ..Sample::default()
        };
        assert_eq!(
            status_rows(server(), &before, &after).maps[0].writes_per_s,
            None
        );
        let same_instant = status_rows(server(), &after, &after);
        assert_eq!(same_instant.maps[0].writes_per_s, None);
    }

    #[test]
    fn lag_and_error_are_measured_against_the_newest_frame_and_the_truth() {
        let after = Sample {
            at_s: 5.0,
            robots: vec![robot("r1", 50, Some(4.9))],
            estimates: vec![EstimateSample {
                robot: "r1".into(),
                map: "m".into(),
                frame_sequence: 45,
                frame_time_s: 4.5,
                converged: true,
                lost_score: 0.25,
                position: (1.0, 1.0),
                true_position: Some((4.0, 5.0)),
                last_arrival_s: Some(4.0),
            }],
            ..Sample::default()
        };
        let status = status_rows(server(), &Sample::default(), &after);
        let row = &status.localizers[0];
        assert_eq!(row.lag_frames, 5);
        assert!((row.lag_s.expect("lag") - 0.5).abs() < 1e-9);
        assert!((row.error_m.expect("error") - 5.0).abs() < 1e-9);
        assert_eq!(row.last_estimate_age_s, Some(1.0));
        assert!(row.converged);
    }

    #[test]
    fn the_json_keys_are_stable() {
        let after = Sample {
            at_s: 1.0,
            maps: vec![map("a", 1)],
            robots: vec![robot("r1", 5, None)],
            estimates: Vec::new(),
        };
        let json = serde_json::to_value(status_rows(server(), &after, &after)).expect("json");
        assert_eq!(json["server"]["health"], "SERVING");
        let mut map_keys: Vec<&String> = json["maps"][0].as_object().expect("map").keys().collect();
        map_keys.sort();
        assert_eq!(
            map_keys,
            [
                "bounds",
                "cells",
                "name",
                "tiles",
                "version",
                "writers",
                "writes_per_s"
            ]
        );
        assert!(json["robots"][0]["last_frame_age_s"].is_null());
        assert!(json["localizers"].as_array().expect("list").is_empty());
    }
}
