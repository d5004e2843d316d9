//! The demo's clock: a tick every quarter second, and ctrl-c or SIGTERM,
//! which ends the demo with an error so that the supervisor, dropped on
//! the way out, stops every process.

use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use anyhow::{Result, bail};
use deog_harness::shutdown_signal;

use crate::status_line::StatusLine;

/// Time between two looks at the processes and the simulator.
const TICK: Duration = Duration::from_millis(250);

/// Ticks until interrupted.
pub(crate) struct Pacer {
    tick: tokio::time::Interval,
    shutdown: Pin<Box<dyn Future<Output = ()> + Send>>,
}

impl Pacer {
    /// Starts the clock and listens for the signals; within the runtime.
    pub fn new() -> Self {
        Self {
            tick: tokio::time::interval(TICK),
            shutdown: Box::pin(shutdown_signal()),
        }
    }

    /// Waits for the next tick. An interrupt is an error: on its way out
    /// the supervisor stops every process.
    pub async fn next(&mut self, status: &mut StatusLine) -> Result<()> {
        tokio::select! {
            () = &mut self.shutdown => {
                status.finish();
                bail!("interrupted: every process of the demo was stopped");
            }
            _ = self.tick.tick() => Ok(()),
        }
    }
}
