//! Estimates of now while the filter is busy: a slow sensor update (a
//! global search, a kidnap, range tables rebuilt) would otherwise leave
//! the robot's last estimate as old as the update is long. Meanwhile a
//! thread beside it takes the frames that arrive and publishes, for the
//! newest, the estimate before the update carried by that frame's odometry
//! (as amcl's pose follows odometry between its updates). The frames go
//! back to the filter afterwards; its own estimate for each replaces the
//! carried one.

use std::time::Duration;

use anyhow::{Context, Result};
use deog_localizer::filter::CarriedEstimate;
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;
use deog_robot_client::convert::pose_from_wire;
use tokio::sync::oneshot;

use super::server::estimate_message;
use crate::frame_queue::FrameQueue;

/// How often the carrier looks for new frames: a tenth of the frames' own
/// period, so a carried estimate is never far behind its frame.
const LOOK_EVERY: Duration = Duration::from_millis(10);

/// A step is carried when the filter holds this many particles (a search:
/// its updates take tens of milliseconds)...
const CARRY_PARTICLES: usize = 5_000;
/// ...or when the last step took this long. Below both a step is over
/// sooner than a thread would start.
const CARRY_AFTER: Duration = Duration::from_millis(5);

/// Whether a step is worth carrying, from the filter's particle count and
/// how long the last step took.
pub(super) fn worth_carrying(particles: usize, last_step: Duration) -> bool {
    particles >= CARRY_PARTICLES || last_step >= CARRY_AFTER
}

/// Where carried estimates go.
pub(super) struct Carrier<'a> {
    pub client: &'a MapClient,
    pub robot: &'a str,
    pub map: &'a str,
}

impl Carrier<'_> {
    /// Runs `step` on this thread while a thread beside it carries
    /// `carried` to the frames that arrive in `queue` past `after`, on
    /// `runtime`. Returns what the step returned and the frames taken,
    /// oldest first.
    pub(super) fn beside<T>(
        &self,
        runtime: &tokio::runtime::Runtime,
        queue: &mut FrameQueue,
        carried: CarriedEstimate,
        after: u64,
        step: impl FnOnce() -> T,
    ) -> Result<(T, Vec<pb::SonarFrame>)> {
        std::thread::scope(|scope| {
            let (done, finished) = oneshot::channel();
            let carrier = scope
                .spawn(move || runtime.block_on(self.carry_until(queue, carried, after, finished)));
            let stepped = step();
            let _ = done.send(());
            let arrived = carrier
                .join()
                .map_err(|_| anyhow::anyhow!("the estimate carrier panicked"))??;
            Ok((stepped, arrived))
        })
    }

    /// Until `done` fires (or its sender is dropped): takes the frames
    /// that arrive in `queue` and publishes `carried` moved to the newest
    /// of them past `after`. Returns the frames taken, oldest first.
    pub(super) async fn carry_until(
        &self,
        queue: &mut FrameQueue,
        carried: CarriedEstimate,
        after: u64,
        mut done: oneshot::Receiver<()>,
    ) -> Result<Vec<pb::SonarFrame>> {
        let mut arrived = Vec::new();
        let mut published = after;
        loop {
            tokio::select! {
                _ = &mut done => break,
                () = tokio::time::sleep(LOOK_EVERY) => {}
            }
            while let Some(frame) = queue.try_next() {
                arrived.push(frame);
            }
            let Some(newest) = arrived.last().filter(|f| f.sequence > published) else {
                continue;
            };
            let Some(odometry) = newest.odometry.map(pose_from_wire) else {
                continue;
            };
            published = newest.sequence;
            let estimate = carried.at(&odometry);
            self.client
                .publish_pose(estimate_message(
                    self.robot,
                    self.map,
                    newest,
                    &estimate,
                    &[],
                ))
                .await
                .with_context(|| {
                    format!(
                        "publishing the carried estimate of frame {}",
                        newest.sequence
                    )
                })?;
        }
        Ok(arrived)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::Pose2;
    use deog_localizer::filter::{FilterSettings, Mcl};
    use deog_robot_client::ClientConfig;
    use deog_robot_client::convert::pose_to_wire;
    use deog_server::{ServerConfig, SledConfig, SledStore};
    use std::sync::Arc;

    fn frame(sequence: u64) -> pb::SonarFrame {
        pb::SonarFrame {
            robot: "r".into(),
            sequence,
            time_s: sequence as f64 * 0.1,
            odometry: Some(pose_to_wire(Pose2::new(0.1 * sequence as f64, 0.0, 0.0))),
            true_pose: None,
            ranges: vec![1.0; 16],
            rig: String::new(),
            reference_pose: None,
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn frames_that_come_meanwhile_get_the_carried_estimate_and_are_handed_back() {
        let dir = tempfile::tempdir().expect("temp dir");
        let store = SledStore::open(&SledConfig::new(dir.path().join("store"))).expect("store");
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr = listener.local_addr().expect("addr");
        let (stop, stopped) = oneshot::channel::<()>();
        let server = tokio::spawn(deog_server::serve(
            Arc::new(store),
            listener,
            ServerConfig::default(),
            async {
                let _ = stopped.await;
            },
        ));
        let client = MapClient::connect(ClientConfig::new(addr.to_string()))
            .await
            .expect("connect");
        client
            .ensure_map(pb::CreateMapRequest {
                name: "m".into(),
                ..Default::default()
            })
            .await
            .expect("map");
        // The filter's estimate at odometry (0, 0, 0): about (2, 3), east.
        let mut mcl = Mcl::new(FilterSettings {
            seed: 1,
            ..FilterSettings::default()
        })
        .expect("filter");
        mcl.start_at(Pose2::new(2.0, 3.0, 0.0), 1e-6, 1e-6)
            .expect("start");
        mcl.predict(&Pose2::new(0.0, 0.0, 0.0)).expect("predict");
        let carried = mcl.carried().expect("an estimate");
        let mut queue = FrameQueue::follow(&client, "r", 0, 0.0)
            .await
            .expect("follow");
        let carrier = Carrier {
            client: &client,
            robot: "r",
            map: "m",
        };
        let (done, finished) = oneshot::channel();
        let publish_then_wait = async {
            client
                .publish_frames((1..=3).map(frame).collect())
                .await
                .expect("frames");
            // Bounded: the carrier looks every 10 ms.
            for _ in 0..500 {
                let poses = client.read_poses("r", 3, 3).await.expect("poses");
                if !poses.is_empty() {
                    break;
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            let _ = done.send(());
        };
        let (arrived, ()) = tokio::join!(
            carrier.carry_until(&mut queue, carried, 0, finished),
            publish_then_wait
        );
        let arrived = arrived.expect("carried");
        let sequences: Vec<u64> = arrived.iter().map(|f| f.sequence).collect();
        assert_eq!(sequences, vec![1, 2, 3]);
        let poses = client.read_poses("r", 1, 3).await.expect("poses");
        let newest = poses.last().expect("an estimate was published");
        assert_eq!(newest.frame_sequence, 3);
        assert_eq!(newest.map, "m");
        let pose = newest.pose.expect("pose");
        // 0.3 m of odometry along the heading it was made at.
        assert!((pose.x - 2.3).abs() < 1e-3, "{pose:?}");
        assert!((pose.y - 3.0).abs() < 1e-3, "{pose:?}");
        let _ = stop.send(());
        let _ = server.await;
    }

    #[test]
    fn searches_and_slow_steps_are_carried_quick_tracking_is_not() {
        assert!(worth_carrying(100_000, Duration::ZERO));
        assert!(worth_carrying(500, Duration::from_millis(40)));
        assert!(!worth_carrying(500, Duration::from_micros(300)));
        assert!(!worth_carrying(CARRY_PARTICLES - 1, CARRY_AFTER / 2));
    }
}
