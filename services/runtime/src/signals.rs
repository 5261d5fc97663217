//! SIGTERM and SIGINT → one cancellation token.

use tokio::signal::unix::{signal, SignalKind};
use tokio_util::sync::CancellationToken;

/// Spawns a task that cancels `token` on the first SIGTERM or SIGINT.
///
/// iceoryx2's own signal handling is disabled in [`crate::ipc`], so this is the only
/// handler in the process.
pub fn spawn_shutdown_on_signal(token: CancellationToken) -> std::io::Result<()> {
    let mut term = signal(SignalKind::terminate())?;
    let mut int = signal(SignalKind::interrupt())?;
    tokio::spawn(async move {
        let which = tokio::select! {
            _ = term.recv() => "SIGTERM",
            _ = int.recv() => "SIGINT",
            _ = token.cancelled() => return,
        };
        tracing::info!(signal = which, "shutdown requested");
        token.cancel();
    });
    Ok(())
}
