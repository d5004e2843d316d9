//! The shutdown signal of long-running subcommands and of the runs that
//! supervise child processes.

/// Resolves on ctrl-c (SIGINT) or, on Unix, SIGTERM. Listens from the
/// call, not from the first poll: a signal that comes between the two is
/// not lost (once any listener exists, the process no longer ends on the
/// signal by itself). Call it inside a Tokio runtime.
pub fn shutdown_signal() -> impl std::future::Future<Output = ()> + Send + 'static {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let listen = |kind: SignalKind, name: &'static str| match signal(kind) {
            Ok(listener) => Some(listener),
            Err(error) => {
                tracing::warn!(%error, "cannot listen for {name}");
                None
            }
        };
        let mut interrupt = listen(SignalKind::interrupt(), "ctrl-c");
        let mut terminate = listen(SignalKind::terminate(), "SIGTERM");
        async move {
            let interrupted = async {
                match interrupt.as_mut() {
                    Some(listener) => listener.recv().await,
                    None => std::future::pending().await,
                }
            };
            let terminated = async {
                match terminate.as_mut() {
                    Some(listener) => listener.recv().await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                _ = interrupted => tracing::info!("ctrl-c received"),
                _ = terminated => tracing::info!("SIGTERM received"),
            }
        }
    }
    #[cfg(not(unix))]
    {
        async {
            if let Err(error) = tokio::signal::ctrl_c().await {
                tracing::warn!(%error, "cannot listen for ctrl-c");
                std::future::pending::<()>().await;
            }
            tracing::info!("ctrl-c received");
        }
    }
}

/// While held, SIGTERM or ctrl-c ends the process at once, exit 0: for the
/// stretches of a run that neither listen for the signal nor hold anything
/// to flush (connecting, waiting for a first frame, building tables), so
/// that no state of a process leaves it deaf to the signal.
#[derive(Debug)]
pub struct ExitOnSignal(tokio::task::JoinHandle<()>);

impl ExitOnSignal {
    /// Listens on `runtime` (a multi-threaded one, so that the listener
    /// runs while the caller's thread works); `doing` names the stretch in
    /// the log.
    pub fn during(doing: &'static str, runtime: &tokio::runtime::Handle) -> Self {
        let _context = runtime.enter();
        let signal = shutdown_signal();
        Self(runtime.spawn(async move {
            signal.await;
            tracing::info!("stopped while {doing}: nothing to flush");
            std::process::exit(0);
        }))
    }
}

impl Drop for ExitOnSignal {
    fn drop(&mut self) {
        self.0.abort();
    }
}
