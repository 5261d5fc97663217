//! TLS for MQTT connections: rustls with the `ring` provider (no aws-lc-rs C build),
//! server certificates checked against a PEM CA bundle from the config. Shared by the
//! cloud connection and the DRC link.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use skymesh_runtime::config::{read_regular_file, FileReadError};
use tokio_rustls::rustls::pki_types::pem::{self, PemObject};
use tokio_rustls::rustls::pki_types::CertificateDer;
use tokio_rustls::rustls::{self, ClientConfig, RootCertStore};

/// Why a CA bundle cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// Missing, unreadable, not a regular file, or larger than [`MAX_CA_FILE_BYTES`].
    #[error("CA bundle: {0}")]
    File(#[from] FileReadError),
    #[error("{path}: not valid PEM: {reason}")]
    Pem { path: PathBuf, reason: String },
    #[error("{0}: no certificate in the file (expected PEM `BEGIN CERTIFICATE` blocks)")]
    NoCertificate(PathBuf),
    #[error("{path}: no usable CA certificate ({rejected} rejected)")]
    NoUsableCertificate { path: PathBuf, rejected: usize },
    #[error("TLS setup: {0}")]
    Rustls(#[from] rustls::Error),
}

/// The largest CA bundle read (the system bundle is about 200 KiB).
pub const MAX_CA_FILE_BYTES: u64 = 1 << 20;

/// What is wrong with a PEM file, in words: `pem::Error`'s own text prints the
/// section label and the bad line as lists of byte values.
fn pem_reason(e: &pem::Error) -> String {
    match e {
        pem::Error::MissingSectionEnd { end_marker } => format!(
            "the `-----END {}-----` line is missing",
            String::from_utf8_lossy(end_marker)
        ),
        pem::Error::IllegalSectionStart { line } => format!(
            "malformed line `{}` (expected `-----BEGIN <LABEL>-----`)",
            String::from_utf8_lossy(line).trim_end()
        ),
        pem::Error::Base64Decode(_) => "a section's body is not valid base64".to_owned(),
        other => other.to_string(),
    }
}

/// The trust anchors of a PEM bundle.
pub fn load_roots(path: &Path) -> Result<RootCertStore, TlsError> {
    let text = read_regular_file(path, MAX_CA_FILE_BYTES)?;
    let certs = CertificateDer::pem_slice_iter(&text)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TlsError::Pem {
            path: path.to_path_buf(),
            reason: pem_reason(&e),
        })?;
    if certs.is_empty() {
        return Err(TlsError::NoCertificate(path.to_path_buf()));
    }
    let mut roots = RootCertStore::empty();
    let (_, rejected) = roots.add_parsable_certificates(certs);
    if roots.is_empty() {
        return Err(TlsError::NoUsableCertificate {
            path: path.to_path_buf(),
            rejected,
        });
    }
    Ok(roots)
}

/// A client config trusting the bundle at `ca_file` (TLS 1.2 and 1.3, ring).
pub fn client_config(ca_file: &Path) -> Result<Arc<ClientConfig>, TlsError> {
    let roots = load_roots(ca_file)?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(Arc::new(config))
}

/// The rumqttc transport for a TLS connection trusting `ca_file`.
pub fn transport(ca_file: &Path) -> Result<rumqttc::Transport, TlsError> {
    Ok(rumqttc::Transport::Tls(rumqttc::TlsConfiguration::Rustls(
        client_config(ca_file)?,
    )))
}

/// A self-signed P-256 CA (CN "skymesh test CA", valid until 2126) for tests.
#[cfg(test)]
pub(crate) const TEST_CA_PEM: &str = "-----BEGIN CERTIFICATE-----
MIIBijCCATGgAwIBAgIUOGRiXEWG6aoJXItbbzk13SWuhAwwCgYIKoZIzj0EAwIw
GjEYMBYGA1UEAwwPc2t5bWVzaCB0ZXN0IENBMCAXDTI2MTEyNTE0NDczN1oYDzIx
MjYxMTAxMTQ0NzM3WjAaMRgwFgYDVQQDDA9za3ltZXNoIHRlc3QgQ0EwWTATBgcq
hkjOPQIBBggqhkjOPQMBBwNCAAQLQCCbYWPVzap9el5ymUY3ETFYXdrH6QvG37Nx
ULAGbrljV7W60HtN7C1Js1SVxxgxJrtH8msNEEmtvSJggz6ao1MwUTAdBgNVHQ4E
FgQUHGSHceXsKxrW+X+EHKC37U3hwdEwHwYDVR0jBBgwFoAUHGSHceXsKxrW+X+E
HKC37U3hwdEwDwYDVR0TAQH/BAUwAwEB/zAKBggqhkjOPQQDAgNHADBEAiBpUede
8HALQuezTG8YyLNZUZRXlLoSacjkH72e2bIPLQIgWORhrV0Ud2kq1V/zlH4b/3mR
zMOvWrNhSWaLzXG478E=
-----END CERTIFICATE-----
";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pem_ca_becomes_a_client_config() {
        let dir = tempfile::tempdir().unwrap();
        let ca = dir.path().join("ca.pem");
        std::fs::write(&ca, TEST_CA_PEM).unwrap();
        assert_eq!(load_roots(&ca).unwrap().len(), 1);
        client_config(&ca).unwrap();
        assert!(matches!(transport(&ca), Ok(rumqttc::Transport::Tls(_))));
    }

    #[test]
    fn unusable_bundles_are_refused_with_the_reason() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.pem");
        assert!(matches!(
            load_roots(&missing),
            Err(TlsError::File(FileReadError::Io { .. }))
        ));
        let empty = dir.path().join("empty.pem");
        std::fs::write(&empty, "").unwrap();
        assert!(matches!(
            load_roots(&empty),
            Err(TlsError::NoCertificate(_))
        ));
        let garbage = dir.path().join("garbage.pem");
        std::fs::write(
            &garbage,
            "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n",
        )
        .unwrap();
        assert!(matches!(
            load_roots(&garbage),
            Err(TlsError::NoUsableCertificate { rejected: 1, .. })
        ));
        // Broken PEM says what is wrong in words.
        let cut = dir.path().join("cut.pem");
        let end = TEST_CA_PEM.find("-----END").unwrap();
        std::fs::write(&cut, &TEST_CA_PEM[..end]).unwrap();
        let e = load_roots(&cut).unwrap_err();
        assert!(matches!(e, TlsError::Pem { .. }), "{e}");
        assert!(
            e.to_string()
                .ends_with("not valid PEM: the `-----END CERTIFICATE-----` line is missing"),
            "{e}"
        );
        let header = dir.path().join("header.pem");
        std::fs::write(
            &header,
            TEST_CA_PEM.replacen("-----BEGIN CERTIFICATE-----", "-----BEGIN CERTIFICATE", 1),
        )
        .unwrap();
        let e = load_roots(&header).unwrap_err().to_string();
        assert!(e.contains("malformed line `-----BEGIN CERTIFICATE`"), "{e}");
        let base64 = dir.path().join("base64.pem");
        std::fs::write(
            &base64,
            "-----BEGIN CERTIFICATE-----\n!!!!\n-----END CERTIFICATE-----\n",
        )
        .unwrap();
        let e = load_roots(&base64).unwrap_err().to_string();
        assert!(e.contains("not valid base64"), "{e}");
    }

    /// Found by the config_files fuzz target: `ca_file = "/dev/zero"` read until memory
    /// ran out, `/dev/stdin` blocked the config check. Devices, directories and
    /// oversized files are refused without being read.
    #[test]
    fn devices_and_huge_files_are_refused_without_reading_them() {
        for dev in ["/dev/zero", "/dev/null"] {
            let e = load_roots(Path::new(dev)).unwrap_err();
            assert!(
                matches!(e, TlsError::File(FileReadError::NotAFile(_))),
                "{dev}: {e}"
            );
        }
        // Whatever stdin is here (a terminal, a pipe, /dev/null, a file), it returns.
        assert!(load_roots(Path::new("/dev/stdin")).is_err());
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            load_roots(dir.path()),
            Err(TlsError::File(FileReadError::NotAFile(_)))
        ));
        let fifo = dir.path().join("ca.fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // Opening a FIFO without a writer would block: refused before opening.
            assert!(matches!(
                load_roots(&fifo),
                Err(TlsError::File(FileReadError::NotAFile(_)))
            ));
        }
        let big = dir.path().join("big.pem");
        let file = std::fs::File::create(&big).unwrap();
        file.set_len(MAX_CA_FILE_BYTES + 1).unwrap();
        let e = load_roots(&big).unwrap_err();
        assert!(
            matches!(e, TlsError::File(FileReadError::TooLarge { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("larger than"), "{e}");
    }
}
