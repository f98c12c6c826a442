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
    /// The private key file can be read by others than its owner.
    #[error(
        "{path}: the private key has mode {mode:o}; it must be readable by its owner only (chmod 600)"
    )]
    KeyPermissions {
        /// The key file.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
    },
    /// Only one of the certificate and its key is there: a new pair would
    /// change the fingerprint clients pin, so nothing is overwritten.
    #[error(
        "{dir} holds {present} without {missing}: restore the pair, or remove it for a new identity"
    )]
    HalfPair {
        /// The identity directory.
        dir: PathBuf,
        /// The file present.
        present: &'static str,
        /// The file missing.
        missing: &'static str,
    },
}

/// The congestion controller of the frames a server sends (`serve
/// --congestion`). Neither is best everywhere; measured through the
/// impairment relay (README, "Impaired networks"): Cubic, loss-based, loses
/// most of the stream to 1 % loss once the path has a few milliseconds of
/// delay; BBR, model-based, keeps it through 10 % loss but sizes its window
/// from the smallest round trip seen, so a path whose delay varies a lot
/// (jitter) starves it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Congestion {
    /// quinn's default, loss-based (RFC 9438).
    #[default]
    Cubic,
    /// quinn's BBR (marked experimental there).
    Bbr,
}

impl std::str::FromStr for Congestion {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "cubic" => Ok(Self::Cubic),
            "bbr" => Ok(Self::Bbr),
            _ => Err(format!("unknown congestion controller `{s}` (cubic, bbr)")),
        }
    }
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
    /// directory has neither. A key file readable by others, or one file of
    /// the pair without the other, is an error (nothing is overwritten).
    /// A new pair is written as a whole: into a temporary directory beside
    /// `dir` that is then renamed to it (where `dir` is absent or empty),
    /// the key with mode 0600.
    pub fn load_or_create(dir: &Path) -> Result<Self, TlsError> {
        let (cert_path, key_path) = (dir.join(CERT_FILE), dir.join(KEY_FILE));
        match (cert_path.exists(), key_path.exists()) {
            (true, true) => {
                check_private(&key_path)?;
                let cert = std::fs::read(&cert_path).map_err(io(&cert_path))?;
                let key = std::fs::read(&key_path).map_err(io(&key_path))?;
                return Ok(Self {
                    cert: CertificateDer::from(cert),
                    key: PrivatePkcs8KeyDer::from(key),
                });
            }
            (true, false) | (false, true) => {
                let (present, missing) = if cert_path.exists() {
                    (CERT_FILE, KEY_FILE)
                } else {
                    (KEY_FILE, CERT_FILE)
                };
                return Err(TlsError::HalfPair {
                    dir: dir.to_owned(),
                    present,
                    missing,
                });
            }
            (false, false) => {}
        }
        let generated =
            rcgen::generate_simple_self_signed(vec!["localhost".into(), "127.0.0.1".into()])?;
        let identity = Self {
            cert: generated.cert.der().clone(),
            key: PrivatePkcs8KeyDer::from(generated.signing_key.serialize_der()),
        };
        identity.save(dir)?;
        Ok(identity)
    }

    /// Writes the pair into `dir` as a whole (see [`Identity::load_or_create`]).
    fn save(&self, dir: &Path) -> Result<(), TlsError> {
        let name = dir
            .file_name()
            .map_or("identity".into(), |n| n.to_string_lossy());
        let staging = dir.with_file_name(format!(".{name}.new-{}", std::process::id()));
        let parent = staging.parent().unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(io(parent))?;
        let _ = std::fs::remove_dir_all(&staging);
        std::fs::create_dir(&staging).map_err(io(&staging))?;
        let write = |at: &Path| -> Result<(), TlsError> {
            let key = at.join(KEY_FILE);
            write_file(&key, self.key.secret_pkcs8_der(), true).map_err(io(&key))?;
            let cert = at.join(CERT_FILE);
            write_file(&cert, self.cert.as_ref(), false).map_err(io(&cert))
        };
        write(&staging)?;
        // rename(2) replaces an absent or empty directory in one step.
        if std::fs::rename(&staging, dir).is_ok() {
            return Ok(());
        }
        // `dir` holds other files: each file of the pair is renamed in.
        let moved = std::fs::create_dir_all(dir)
            .and_then(|()| std::fs::rename(staging.join(KEY_FILE), dir.join(KEY_FILE)))
            .and_then(|()| std::fs::rename(staging.join(CERT_FILE), dir.join(CERT_FILE)));
        let _ = std::fs::remove_dir_all(&staging);
        moved.map_err(io(dir))
    }

    /// The QUIC endpoint configuration for this identity: its stateless
    /// reset key and its connection-id key are derived from the private
    /// key, so a server restarted with the same identity recognises the
    /// connection ids it issued before and answers their packets with a
    /// reset its clients accept (RFC 9000 §10.3): they reconnect at once
    /// instead of waiting out their idle timeout.
    pub fn quic_endpoint_config(&self) -> quinn::EndpointConfig {
        let derive = ring::hmac::Key::new(ring::hmac::HMAC_SHA256, self.key.secret_pkcs8_der());
        let secret = |label: &[u8]| ring::hmac::sign(&derive, label);
        let reset = secret(b"framegen QUIC stateless reset key");
        let mut config = quinn::EndpointConfig::new(Arc::new(ring::hmac::Key::new(
            ring::hmac::HMAC_SHA256,
            reset.as_ref(),
        )));
        let cid = secret(b"framegen QUIC connection id key");
        let mut cid_key = [0u8; 8];
        cid_key.copy_from_slice(&cid.as_ref()[..8]);
        let cid_key = u64::from_le_bytes(cid_key);
        config.cid_generator(move || {
            Box::new(quinn_proto::HashedConnectionIdGenerator::from_key(cid_key))
        });
        config
    }

    /// The QUIC server configuration for this identity, its frames sent
    /// under `congestion` control.
    pub fn quic_server_config(
        &self,
        congestion: Congestion,
    ) -> Result<quinn::ServerConfig, TlsError> {
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
        if congestion == Congestion::Bbr {
            transport
                .congestion_controller_factory(Arc::new(quinn::congestion::BbrConfig::default()));
        }
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

/// The certificate's file name in an identity directory.
const CERT_FILE: &str = "cert.der";
/// The private key's file name in an identity directory.
const KEY_FILE: &str = "key.der";

/// Maps an I/O error on `path` to a [`TlsError`].
fn io(path: &Path) -> impl FnOnce(std::io::Error) -> TlsError + use<> {
    let path = path.to_owned();
    move |source| TlsError::Io { path, source }
}

/// Writes and syncs a new file; a private one with mode 0600 from the
/// start (never readable by others, not even briefly).
fn write_file(path: &Path, bytes: &[u8], private: bool) -> std::io::Result<()> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    if private {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    #[cfg(not(unix))]
    let _ = private;
    let mut file = options.open(path)?;
    file.write_all(bytes)?;
    file.sync_all()
}

/// A private key must be readable by its owner only.
fn check_private(path: &Path) -> Result<(), TlsError> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(path)
            .map_err(io(path))?
            .permissions()
            .mode()
            & 0o777;
        if mode & 0o077 != 0 {
            return Err(TlsError::KeyPermissions {
                path: path.to_owned(),
                mode,
            });
        }
    }
    #[cfg(not(unix))]
    let _ = path;
    Ok(())
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
        a.quic_server_config(Congestion::Cubic).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(dir.path().join("key.der"))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        // A key others can read is refused, and so is half a pair; nothing
        // is overwritten.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let key = dir.path().join("key.der");
            std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
            assert!(matches!(
                Identity::load_or_create(dir.path()),
                Err(TlsError::KeyPermissions { mode: 0o644, .. })
            ));
            std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        }
        std::fs::remove_file(dir.path().join("key.der")).unwrap();
        assert!(matches!(
            Identity::load_or_create(dir.path()),
            Err(TlsError::HalfPair {
                present: "cert.der",
                ..
            })
        ));
        assert!(dir.path().join("cert.der").exists());
        // A new identity in a directory that does not exist yet, and in one
        // that holds other files; no staging directory is left behind.
        let parent = tempfile::tempdir().unwrap();
        let fresh = parent.path().join("new").join("identity");
        Identity::load_or_create(&fresh).unwrap();
        std::fs::write(parent.path().join("new").join("notes"), b"x").unwrap();
        let crowded = parent.path().join("new");
        let c = Identity::load_or_create(&crowded).unwrap();
        assert_eq!(
            Identity::load_or_create(&crowded).unwrap().fingerprint(),
            c.fingerprint()
        );
        let names: Vec<_> = std::fs::read_dir(parent.path().join("new"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
        let other = tempfile::tempdir().unwrap();
        assert_ne!(
            Identity::load_or_create(other.path())
                .unwrap()
                .fingerprint(),
            a.fingerprint()
        );
    }

    #[test]
    fn congestion_controllers_parse_by_name() {
        assert_eq!("bbr".parse(), Ok(Congestion::Bbr));
        assert_eq!("cubic".parse(), Ok(Congestion::Cubic));
        assert!(
            "reno"
                .parse::<Congestion>()
                .unwrap_err()
                .contains("cubic, bbr")
        );
        let dir = tempfile::tempdir().unwrap();
        let id = Identity::load_or_create(dir.path()).unwrap();
        for c in [Congestion::Cubic, Congestion::Bbr] {
            id.quic_server_config(c).unwrap();
        }
    }
}
