//! Certificate pinning (DESIGN §7). The server's certificate is self-signed,
//! so the client trusts exactly one certificate: the one whose SHA-256 it
//! was given, or the one in a file. The TLS 1.3 handshake signature is still
//! verified against that certificate's key.
//!
//! Accepting any certificate exists only as
//! [`Pin::DangerousAcceptAnyCertificate`], for tests and debugging; it is
//! never a default.

use std::path::PathBuf;
use std::sync::Arc;

use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::{CryptoProvider, verify_tls12_signature, verify_tls13_signature};
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use rustls::{DigitallySignedStruct, SignatureScheme};
use sha2::{Digest, Sha256};

/// ALPN of the stream protocol (must match the server's).
pub const ALPN: &[u8] = b"framegen-stream/1";

/// Which server certificate to trust.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Pin {
    /// SHA-256 of the certificate DER, hex (colons and case ignored).
    Sha256(String),
    /// The certificate itself (DER file, as the server saves it).
    CertFile(PathBuf),
    /// Trust any certificate: no protection against impersonation.
    DangerousAcceptAnyCertificate,
}

/// A pin that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PinError {
    /// The fingerprint is not 64 hex digits.
    #[error("fingerprint must be 64 hex digits (SHA-256), got {0:?}")]
    BadFingerprint(String),
    /// rustls refused the configuration.
    #[error("TLS configuration: {0}")]
    Tls(#[from] rustls::Error),
    /// The certificate file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}

impl Pin {
    /// The expected SHA-256, or `None` for the dangerous mode.
    fn digest(&self) -> Result<Option<[u8; 32]>, PinError> {
        match self {
            Pin::Sha256(hex) => {
                let clean: String = hex
                    .chars()
                    .filter(|c| *c != ':')
                    .collect::<String>()
                    .to_lowercase();
                let bad = || PinError::BadFingerprint(hex.clone());
                // Digits only, checked before any pair is taken: a
                // multi-byte character must not split (issue 18 §5).
                let digits = clean.as_bytes();
                if digits.len() != 64 || !digits.iter().all(u8::is_ascii_hexdigit) {
                    return Err(bad());
                }
                let nibble = |d: u8| (d as char).to_digit(16).unwrap_or(0) as u8;
                let mut out = [0u8; 32];
                for (byte, pair) in out.iter_mut().zip(digits.chunks_exact(2)) {
                    *byte = nibble(pair[0]) << 4 | nibble(pair[1]);
                }
                Ok(Some(out))
            }
            Pin::CertFile(path) => {
                let der = std::fs::read(path).map_err(|source| PinError::Io {
                    path: path.clone(),
                    source,
                })?;
                Ok(Some(Sha256::digest(&der).into()))
            }
            Pin::DangerousAcceptAnyCertificate => Ok(None),
        }
    }

    /// The rustls client configuration that enforces this pin (TLS 1.3).
    pub fn client_config(&self) -> Result<rustls::ClientConfig, PinError> {
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let verifier = Arc::new(PinVerifier {
            expected: self.digest()?,
            provider: provider.clone(),
        });
        let mut config = rustls::ClientConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13])?
            .dangerous()
            .with_custom_certificate_verifier(verifier)
            .with_no_client_auth();
        config.alpn_protocols = vec![ALPN.to_vec()];
        Ok(config)
    }
}

#[derive(Debug)]
struct PinVerifier {
    expected: Option<[u8; 32]>,
    provider: Arc<CryptoProvider>,
}

impl ServerCertVerifier for PinVerifier {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        match self.expected {
            None => Ok(ServerCertVerified::assertion()),
            Some(want) => {
                let got: [u8; 32] = Sha256::digest(end_entity.as_ref()).into();
                if got == want {
                    Ok(ServerCertVerified::assertion())
                } else {
                    Err(rustls::Error::General(format!(
                        "server certificate does not match the pin (its SHA-256 is {})",
                        got.iter().map(|b| format!("{b:02x}")).collect::<String>()
                    )))
                }
            }
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        verify_tls12_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        verify_tls13_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.provider
            .signature_verification_algorithms
            .supported_schemes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprints_parse_with_or_without_colons() {
        let hex = "AB".repeat(32);
        let colons = vec!["ab"; 32].join(":");
        assert_eq!(Pin::Sha256(hex).digest().unwrap(), Some([0xab; 32]));
        assert_eq!(Pin::Sha256(colons).digest().unwrap(), Some([0xab; 32]));
        assert!(Pin::Sha256("abc".into()).digest().is_err());
        assert!(Pin::Sha256("zz".repeat(32)).digest().is_err());
        // 64 bytes of two-byte characters: an error, not a panic on a
        // character boundary.
        assert!(Pin::Sha256("é".repeat(32)).digest().is_err());
        assert!(
            Pin::Sha256(format!("{}é", "a".repeat(62)))
                .digest()
                .is_err()
        );
        assert!(
            Pin::CertFile("/nonexistent/cert.der".into())
                .digest()
                .is_err()
        );
        assert_eq!(Pin::DangerousAcceptAnyCertificate.digest().unwrap(), None);
    }
}
