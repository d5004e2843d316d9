//! [`SimClient`]: typed calls to the simulator's `RobotService`, the way a
//! robot process drives its (simulated) Scout.

use crate::connect::{ClientConfig, TokenInterceptor, connect, with_retry};
use crate::convert::pose_to_wire;
use crate::error::ClientError;
use deog_grid::Pose2;
use deog_proto::v1 as pb;
use deog_proto::v1::robot_service_client::RobotServiceClient;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;

/// The generated robot-service client with the token interceptor.
type RawSimClient = RobotServiceClient<InterceptedService<Channel, TokenInterceptor>>;

/// A connection to the simulator; cheap to clone.
#[derive(Debug, Clone)]
pub struct SimClient {
    raw: RawSimClient,
    config: ClientConfig,
}

impl SimClient {
    /// Connects, retrying with backoff while the simulator is not up yet.
    pub async fn connect(mut config: ClientConfig) -> Result<Self, ClientError> {
        // Whatever the configuration says, this reaches a simulator.
        config.peer = crate::Peer::Simulator;
        let (channel, interceptor) = connect(&config).await?;
        Ok(Self {
            raw: RobotServiceClient::with_interceptor(channel, interceptor),
            config,
        })
    }

    /// Places a robot at `pose`, or at a random free pose when `None`.
    pub async fn spawn(
        &self,
        name: &str,
        pose: Option<Pose2>,
    ) -> Result<pb::RobotState, ClientError> {
        let request = pb::SpawnRequest {
            name: name.to_string(),
            pose: pose.map(pose_to_wire),
        };
        let raw = self.raw.clone();
        let state = with_retry(&self.config.retry, || {
            let (mut raw, request) = (raw.clone(), request.clone());
            async move { raw.spawn(request).await }
        })
        .await?;
        Ok(state.into_inner())
    }

    /// Sets the robot's velocity command (m/s, rad/s); the reply says what
    /// the robot executes after clamping.
    pub async fn drive(
        &self,
        name: &str,
        linear: f64,
        angular: f64,
    ) -> Result<pb::RobotState, ClientError> {
        let request = pb::DriveRequest {
            name: name.to_string(),
            command: Some(pb::Twist2 { linear, angular }),
        };
        let raw = self.raw.clone();
        let state = with_retry(&self.config.retry, || {
            let (mut raw, request) = (raw.clone(), request.clone());
            async move { raw.drive(request).await }
        })
        .await?;
        Ok(state.into_inner())
    }

    /// The robot's current state (the thesis's `gs()`).
    pub async fn state(&self, name: &str) -> Result<pb::RobotState, ClientError> {
        let request = pb::RobotRef {
            name: name.to_string(),
        };
        let raw = self.raw.clone();
        let state = with_retry(&self.config.retry, || {
            let (mut raw, request) = (raw.clone(), request.clone());
            async move { raw.get_state(request).await }
        })
        .await?;
        Ok(state.into_inner())
    }

    /// Moves the robot without telling its odometry (a kidnapping).
    pub async fn teleport(&self, name: &str, pose: Pose2) -> Result<pb::RobotState, ClientError> {
        let request = pb::TeleportRequest {
            name: name.to_string(),
            pose: Some(pose_to_wire(pose)),
        };
        let raw = self.raw.clone();
        let state = with_retry(&self.config.retry, || {
            let (mut raw, request) = (raw.clone(), request.clone());
            async move { raw.teleport(request).await }
        })
        .await?;
        Ok(state.into_inner())
    }

    /// Every robot in the world.
    pub async fn robots(&self) -> Result<Vec<pb::RobotState>, ClientError> {
        let raw = self.raw.clone();
        let reply = with_retry(&self.config.retry, || {
            let mut raw = raw.clone();
            async move { raw.list_robots(pb::ListSimRobotsRequest {}).await }
        })
        .await?;
        Ok(reply.into_inner().robots)
    }

    /// The world's name, bounds and sensor figures.
    pub async fn world(&self) -> Result<pb::WorldInfo, ClientError> {
        let raw = self.raw.clone();
        let reply = with_retry(&self.config.retry, || {
            let mut raw = raw.clone();
            async move { raw.get_world(pb::GetWorldRequest {}).await }
        })
        .await?;
        Ok(reply.into_inner())
    }

    /// The robot's state now and after each sonar firing.
    pub async fn watch(&self, name: &str) -> Result<tonic::Streaming<pb::RobotState>, ClientError> {
        let request = pb::RobotRef {
            name: name.to_string(),
        };
        Ok(self.raw.clone().watch_state(request).await?.into_inner())
    }
}
