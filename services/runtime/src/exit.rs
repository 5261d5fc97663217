//! Exit codes are a contract with the supervisor and systemd.

/// Clean exit (SIGTERM handled, work finished).
pub const OK: u8 = 0;
/// Runtime failure: restarted with backoff.
pub const FAILURE: u8 = 1;
/// Bad configuration (`EX_USAGE`): never restarted, state `config-error`.
pub const CONFIG: u8 = 64;
