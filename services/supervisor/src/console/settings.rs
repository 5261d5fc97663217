//! The console's keys of `[supervisor]` (`console_token`, `console_token_file`,
//! `console_remote`) → [`ConsoleSettings`], and the token check.
//!
//! The token guards the console's actions (restart a service, emergency stop). It
//! is compared in constant time; it never appears in logs or `Debug` output.

use std::path::{Path, PathBuf};

use skymesh_runtime::config::{read_regular_file, FileReadError};
use skymesh_runtime::ConfigError;

/// Shortest token accepted: a guessable token would make the check pointless.
pub const MIN_TOKEN_CHARS: usize = 16;
/// Longest token accepted (it travels in an HTTP header).
pub const MAX_TOKEN_CHARS: usize = 256;
/// Largest `console_token_file` read.
const MAX_TOKEN_FILE_BYTES: u64 = 4096;

/// The secret that unlocks the console's actions.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(String);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(<redacted>)")
    }
}

impl Token {
    /// Checks `text` against the token rules (16..=256 visible ASCII characters,
    /// no spaces), naming `field` on error.
    pub fn parse(field: &str, text: &str) -> Result<Token, ConfigError> {
        let n = text.chars().count();
        if !(MIN_TOKEN_CHARS..=MAX_TOKEN_CHARS).contains(&n) {
            return Err(ConfigError::invalid(
                field,
                format!(
                    "the token has {n} characters; use {MIN_TOKEN_CHARS}..={MAX_TOKEN_CHARS} \
                     (e.g. `openssl rand -hex 24`)"
                ),
            ));
        }
        if !text.bytes().all(|b| b.is_ascii_graphic()) {
            return Err(ConfigError::invalid(
                field,
                "the token must be visible ASCII characters without spaces",
            ));
        }
        Ok(Token(text.to_string()))
    }

    /// True when `offered` is this token; takes the same time for every offered
    /// token of the same length, whichever byte differs.
    pub fn matches(&self, offered: &[u8]) -> bool {
        constant_time_eq(self.0.as_bytes(), offered)
    }
}

/// Equal bytes, compared without an early exit (a length mismatch returns at once:
/// the length is not the secret).
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The console's settings.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConsoleSettings {
    /// The actions' token; `None`: the console shows the mesh and offers no action.
    pub token: Option<Token>,
    /// Where the token is read from ([`ConsoleSettings::read_token_file`]), if it
    /// is kept out of `skymesh.toml`.
    pub token_file: Option<PathBuf>,
    /// Serve the console (page, JSON, actions) to peers other than loopback too.
    pub remote: bool,
}

impl ConsoleSettings {
    /// From the raw keys; `base` resolves a relative `console_token_file`.
    pub fn from_raw(
        token: Option<&str>,
        token_file: Option<&str>,
        remote: bool,
        base: &Path,
    ) -> Result<ConsoleSettings, ConfigError> {
        let token_file = match (token, token_file) {
            (Some(_), Some(_)) => {
                return Err(ConfigError::invalid(
                    "supervisor.console_token_file",
                    "set either console_token or console_token_file, not both",
                ))
            }
            (_, Some("")) => {
                return Err(ConfigError::invalid(
                    "supervisor.console_token_file",
                    "must not be empty (leave the key out for no token)",
                ))
            }
            (_, Some(f)) => Some(base.join(f)),
            (_, None) => None,
        };
        let token = token
            .map(|t| Token::parse("supervisor.console_token", t))
            .transpose()?;
        Ok(ConsoleSettings {
            token,
            token_file,
            remote,
        })
    }

    /// Reads `token_file` (a regular file of at most 4 KiB; surrounding whitespace
    /// such as the final newline is ignored) into `token`. Nothing to do without one.
    pub fn read_token_file(&mut self) -> Result<(), ConfigError> {
        let Some(path) = &self.token_file else {
            return Ok(());
        };
        const FIELD: &str = "supervisor.console_token_file";
        let bytes = read_regular_file(path, MAX_TOKEN_FILE_BYTES).map_err(|e| match e {
            FileReadError::Io { path, source } => {
                ConfigError::invalid(FIELD, format!("cannot read {}: {source}", path.display()))
            }
            other => ConfigError::invalid(FIELD, other.to_string()),
        })?;
        let text = String::from_utf8(bytes).map_err(|_| {
            ConfigError::invalid(FIELD, format!("{} is not UTF-8 text", path.display()))
        })?;
        self.token = Some(Token::parse(FIELD, text.trim())?);
        Ok(())
    }

    /// Whether the actions exist at all.
    pub fn actions(&self) -> bool {
        self.token.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "0123456789abcdef-token";

    #[test]
    fn tokens_need_length_and_visible_ascii() {
        assert!(Token::parse("f", GOOD).is_ok());
        for bad in [
            "short",
            "has a space in it ok",
            "tab\tinside-the-token",
            "ünïcödé-but-long-enough",
        ] {
            let e = Token::parse("f", bad).unwrap_err();
            assert!(e.to_string().contains('f'), "{bad}: {e}");
        }
        assert!(Token::parse("f", &"x".repeat(MAX_TOKEN_CHARS + 1)).is_err());
        assert_eq!(
            format!("{:?}", Token::parse("f", GOOD).unwrap()),
            "Token(<redacted>)"
        );
    }

    #[test]
    fn matching_is_exact() {
        let t = Token::parse("f", GOOD).unwrap();
        assert!(t.matches(GOOD.as_bytes()));
        assert!(!t.matches(b"0123456789abcdef-tokeN"));
        assert!(!t.matches(b"0123456789abcdef-toke"));
        assert!(!t.matches(b""));
    }

    #[test]
    fn one_source_at_most_and_the_file_is_read_trimmed() {
        let base = Path::new("/nonexistent");
        let e = ConsoleSettings::from_raw(Some(GOOD), Some("t"), false, base).unwrap_err();
        assert!(e.to_string().contains("not both"), "{e}");
        assert!(ConsoleSettings::from_raw(None, Some(""), false, base).is_err());
        let none = ConsoleSettings::from_raw(None, None, false, base).unwrap();
        assert!(!none.actions());

        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("token"), format!("{GOOD}\n")).unwrap();
        let mut s = ConsoleSettings::from_raw(None, Some("token"), true, dir.path()).unwrap();
        assert!(!s.actions(), "not read yet");
        s.read_token_file().unwrap();
        assert!(s.token.as_ref().unwrap().matches(GOOD.as_bytes()));
        assert!(s.remote);

        let mut missing = ConsoleSettings::from_raw(None, Some("nope"), false, dir.path()).unwrap();
        let e = missing.read_token_file().unwrap_err();
        assert!(e.to_string().contains("console_token_file"), "{e}");
        std::fs::write(dir.path().join("short"), "abc\n").unwrap();
        let mut short = ConsoleSettings::from_raw(None, Some("short"), false, dir.path()).unwrap();
        assert!(short.read_token_file().is_err());
        let mut dev =
            ConsoleSettings::from_raw(None, Some("/dev/zero"), false, dir.path()).unwrap();
        assert!(dev.read_token_file().is_err());
    }
}
