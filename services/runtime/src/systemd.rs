//! systemd readiness and watchdog, a no-op when not run by systemd.

/// True when started by systemd with `Type=notify`.
pub fn under_systemd() -> bool {
    std::env::var_os("NOTIFY_SOCKET").is_some()
}

/// Tells systemd the service is ready (`READY=1`).
pub fn notify_ready() {
    if under_systemd() {
        if let Err(e) = sd_notify::notify(&[sd_notify::NotifyState::Ready]) {
            tracing::warn!(error = %e, "sd_notify READY failed");
        }
    }
}

/// Tells systemd the service is stopping.
pub fn notify_stopping() {
    if under_systemd() {
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    }
}

/// The watchdog period systemd expects pings within, if it set one.
pub fn watchdog_interval() -> Option<std::time::Duration> {
    if !under_systemd() {
        return None;
    }
    sd_notify::watchdog_enabled()
}

/// Pings the systemd watchdog (`WATCHDOG=1`).
pub fn notify_watchdog() {
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
}
