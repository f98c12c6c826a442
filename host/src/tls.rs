//! The server's TLS identity (DESIGN §7): a self-signed certificate made with
//! `rcgen` on first start and persisted, so clients can pin it by its SHA-256
//! fingerprint; and the QUIC server configuration (TLS 1.3 only, ALPN
//! [`ALPN`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer};
use sha2::{Digest, Sha256};

/// The application protocol negotiated in the TLS handshake.
pub const ALPN: &[u8] = b"framegen-stream/1";

/// Why the identity or the TLS configuration could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// Reading or writing the identity files failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Generating the certificate failed.
    #[error("generating the certificate: {0}")]
    Generate(#[from] rcgen::Error),
    /// rustls refused the configuration or the key.
    #[error("TLS configuration: {0}")]
    Rustls(#[from] rustls::Error),
    /// quinn refused the TLS configuration.
    #[error("QUIC TLS configuration: {0}")]
    Quic(String),
}

/// A certificate and its private key.
#[derive(Debug)]
pub struct Identity {
    /// The self-signed certificate, DER.
    pub cert: CertificateDer<'static>,
    /// Its PKCS#8 private key, DER.
    pub key: PrivatePkcs8KeyDer<'static>,
}

impl Identity {
    /// SHA-256 of the certificate DER, lowercase hex: what clients pin.
    pub fn fingerprint(&self) -> String {
        fingerprint(&self.cert)
    }

    /// Loads the identity from `dir` (`cert.der`, `key.der`), or creates and
    /// saves a new one for the names `localhost` and `127.0.0.1` if the
    /// directory has none. The key file is written with mode 0600.
    pub fn load_or_create(dir: &Path) -> Result<Self, TlsError> {
        let (cert_path, key_path) = (dir.join("cert.der"), dir.join("key.der"));
        let io = |path: &Path| {
            let path = path.to_owned();
            move |source| TlsError::Io { path, source }
        };
        if cert_path.exists() && key_path.exists() {
            let cert = std::fs::read(&cert_path).map_err(io(&cert_path))?;
            let key = std::fs::read(&key_path).map_err(io(&key_path))?;
            return Ok(Self {
                cert: CertificateDer::from(cert),
                key: PrivatePkcs8KeyDer::from(key),
            });
        }
        let generated =
            rcgen::generate_simple_self_signed(vec!["localhost".into(), "127.0.0.1".into()])?;
        let identity = Self {
            cert: generated.cert.der().clone(),
            key: PrivatePkcs8KeyDer::from(generated.signing_key.serialize_der()),
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        write_private(&key_path, identity.key.secret_pkcs8_der()).map_err(io(&key_path))?;
        std::fs::write(&cert_path, identity.cert.as_ref()).map_err(io(&cert_path))?;
        Ok(identity)
    }

    /// The QUIC server configuration for this identity.
    pub fn quic_server_config(&self) -> Result<quinn::ServerConfig, TlsError> {
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut tls = rustls::ServerConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13])?
            .with_no_client_auth()
            .with_single_cert(
                vec![self.cert.clone()],
                PrivateKeyDer::Pkcs8(self.key.clone_key()),
            )?;
        tls.alpn_protocols = vec![ALPN.to_vec()];
        let crypto = quinn::crypto::rustls::QuicServerConfig::try_from(tls)
            .map_err(|e| TlsError::Quic(e.to_string()))?;
        let mut config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
        let mut transport = quinn::TransportConfig::default();
        // What a client may send: its control stream and nothing else
        // (frames flow the other way, on streams the server opens under the
        // client's limits), with receive windows sized for control messages
        // and input datagrams, not frames (issue 18 §2).
        transport
            .max_concurrent_uni_streams(0u32.into())
            .max_concurrent_bidi_streams(1u32.into())
            .stream_receive_window(CONTROL_WINDOW.into())
            .receive_window((4 * CONTROL_WINDOW).into())
            .datagram_receive_buffer_size(Some(CONTROL_WINDOW as usize))
            // Frames are large: let a few be in flight at once.
            .send_window(256 << 20)
            .keep_alive_interval(Some(std::time::Duration::from_secs(2)));
        config.transport_config(Arc::new(transport));
        Ok(config)
    }
}

/// The server's receive window per stream, bytes: a few control messages
/// (each at most `Limits::MAX_CONTROL_STREAM`).
pub const CONTROL_WINDOW: u32 = 64 * 1024;

/// SHA-256 of a certificate's DER, lowercase hex.
pub fn fingerprint(cert: &CertificateDer<'_>) -> String {
    Sha256::digest(cert.as_ref())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn write_private(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    options.open(path)?.write_all(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_persists_and_keeps_its_fingerprint() {
        let dir = tempfile::tempdir().unwrap();
        let a = Identity::load_or_create(dir.path()).unwrap();
        let b = Identity::load_or_create(dir.path()).unwrap();
        assert_eq!(a.fingerprint(), b.fingerprint());
        assert_eq!(a.fingerprint().len(), 64);
        a.quic_server_config().unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(dir.path().join("key.der"))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let other = tempfile::tempdir().unwrap();
        assert_ne!(
            Identity::load_or_create(other.path())
                .unwrap()
                .fingerprint(),
            a.fingerprint()
        );
    }
}
