//! Mutual authentication by a shared secret: each side sends a fresh nonce, then an HMAC-SHA256 over both
//! nonces and its own role, and checks the peer's in constant time. The secret never crosses the wire and is
//! never printed; a proof cannot be replayed (fresh nonces) or reflected (the role is inside the MAC).

use super::connection::Connection;
use super::error::ProtocolError;
use super::message::{Message, Role, PROTOCOL_VERSION};
use hmac::{Hmac, Mac};
use sha2::Sha256;
use std::path::Path;
use std::time::Duration;

/// The shared secret's file in a key folder, which `keys init` writes beside the certificates (`super::tls`).
pub const SECRET_FILE: &str = "secret";

/// The environment variable a secret may come from.
pub const SECRET_ENV: &str = "PHOTONFARM_SECRET";

/// A shared secret. `Debug` does not show it.
#[derive(Clone)]
pub struct Secret {
    key: Vec<u8>,
    insecure: bool,
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.insecure {
            f.write_str("Secret(insecure)")
        } else {
            write!(f, "Secret({} bytes)", self.key.len())
        }
    }
}

/// Why no secret could be had.
#[derive(Debug, thiserror::Error)]
pub enum SecretError {
    #[error("cannot read the secret file {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("the secret in {0} is shorter than 16 bytes")]
    TooShort(String),
    #[error(
        "a link that is not loopback needs a shared secret: --secret-file FILE, ${SECRET_ENV} or the secret of \
         --tls-dir DIR (or --insecure to let anyone who can reach the port in)"
    )]
    Missing,
}

impl Secret {
    /// A secret from bytes (at least 16 of them, after trimming surrounding white space).
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, SecretError> {
        let text = bytes.trim_ascii();
        if text.len() < 16 {
            return Err(SecretError::TooShort(origin.into()));
        }
        Ok(Secret { key: text.to_vec(), insecure: false })
    }

    /// The secret stored in a file.
    pub fn from_file(path: &Path) -> Result<Self, SecretError> {
        let bytes =
            std::fs::read(path).map_err(|source| SecretError::Read { path: path.display().to_string(), source })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// The secret of a program's command line, looked for in this order: `--secret-file`, `$PHOTONFARM_SECRET`,
    /// the `secret` file of `--tls-dir`. Without any, the empty secret of `--insecure` where `insecure_allowed`
    /// (`--insecure` given, or every link on loopback), otherwise `SecretError::Missing`.
    pub fn resolve(
        secret_file: Option<&Path>,
        tls_dir: Option<&Path>,
        insecure_allowed: bool,
    ) -> Result<Self, SecretError> {
        if let Some(path) = secret_file {
            return Self::from_file(path);
        }
        if let Some(s) = Self::from_env()? {
            return Ok(s);
        }
        if let Some(path) = tls_dir.map(|d| d.join(SECRET_FILE)).filter(|p| p.exists()) {
            return Self::from_file(&path);
        }
        if insecure_allowed {
            return Ok(Self::insecure());
        }
        Err(SecretError::Missing)
    }

    /// The secret in `PHOTONFARM_SECRET`, if set.
    pub fn from_env() -> Result<Option<Self>, SecretError> {
        match std::env::var_os(SECRET_ENV) {
            Some(v) => Ok(Some(Self::from_bytes(v.as_encoded_bytes(), SECRET_ENV)?)),
            None => Ok(None),
        }
    }

    /// A fresh random secret (32 bytes, hex) for the workers a coordinator starts itself.
    pub fn random() -> Self {
        let mut raw = [0u8; 32];
        getrandom::fill(&mut raw).expect("the operating system's random source failed");
        let hex: String = raw.iter().map(|b| format!("{b:02x}")).collect();
        Secret { key: hex.into_bytes(), insecure: false }
    }

    /// The empty secret of `--insecure` links: both sides must say so.
    pub fn insecure() -> Self {
        Secret { key: Vec::new(), insecure: true }
    }

    /// True for the secret of `--insecure`.
    pub fn is_insecure(&self) -> bool {
        self.insecure
    }

    /// True when `candidate` (surrounding white space trimmed) is this secret, compared in constant time over
    /// the candidate's bytes; never true for the empty secret of `--insecure`.
    pub fn matches(&self, candidate: &[u8]) -> bool {
        let candidate = candidate.trim_ascii();
        if self.insecure || candidate.len() != self.key.len() {
            return false;
        }
        candidate.iter().zip(&self.key).fold(0u8, |acc, (a, b)| acc | (a ^ b)) == 0
    }

    /// The secret's text, to hand to a child process through its environment.
    pub fn expose_for_child(&self) -> &[u8] {
        &self.key
    }

    fn proof(&self, role: Role, sender_nonce: &[u8; 32], receiver_nonce: &[u8; 32]) -> Hmac<Sha256> {
        let mut mac = Hmac::<Sha256>::new_from_slice(&self.key).expect("HMAC takes keys of any length");
        mac.update(b"photonfarm proof v1");
        mac.update(&PROTOCOL_VERSION.to_le_bytes());
        mac.update(&[role as u8]);
        mac.update(sender_nonce);
        mac.update(receiver_nonce);
        mac
    }
}

/// Who the peer said it is.
#[derive(Clone, Debug)]
pub struct Peer {
    pub name: String,
    pub role: Role,
}

/// How long each handshake step may take.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// Runs the handshake as `role`; on failure the peer is told why (when it can be) and the error returned.
pub async fn handshake(conn: &mut Connection, role: Role, name: &str, secret: &Secret) -> Result<Peer, ProtocolError> {
    let mut nonce = [0u8; 32];
    getrandom::fill(&mut nonce).map_err(|e| ProtocolError::Io(std::io::Error::other(e.to_string())))?;
    conn.write(&Message::Hello { version: PROTOCOL_VERSION, role, nonce, name: name.into() }).await?;
    let (peer_nonce, peer) = match conn.read_within(HANDSHAKE_TIMEOUT, "Hello").await? {
        Message::Hello { version, role: peer_role, nonce, name } => {
            if version != PROTOCOL_VERSION {
                let err = ProtocolError::Version { ours: PROTOCOL_VERSION, theirs: version };
                let _ = conn.write(&Message::Refused { reason: err.to_string() }).await;
                return Err(err);
            }
            if peer_role == role {
                let reason = format!("both ends are a {role:?}");
                let _ = conn.write(&Message::Refused { reason: reason.clone() }).await;
                return Err(ProtocolError::Refused(reason));
            }
            (nonce, Peer { name, role: peer_role })
        }
        Message::Refused { reason } => return Err(ProtocolError::Refused(reason)),
        other => return Err(ProtocolError::Unexpected { expected: "Hello", got: other.kind().into() }),
    };
    let mac: [u8; 32] = secret.proof(role, &nonce, &peer_nonce).finalize().into_bytes().into();
    conn.write(&Message::Proof { mac }).await?;
    match conn.read_within(HANDSHAKE_TIMEOUT, "Proof").await? {
        Message::Proof { mac } => {
            // `verify_slice` compares in constant time.
            if secret.proof(peer.role, &peer_nonce, &nonce).verify_slice(&mac).is_err() {
                let _ = conn.write(&Message::Refused { reason: "authentication failed".into() }).await;
                return Err(ProtocolError::Authentication);
            }
            Ok(peer)
        }
        Message::Refused { reason } if reason == "authentication failed" => Err(ProtocolError::Authentication),
        Message::Refused { reason } => Err(ProtocolError::Refused(reason)),
        other => Err(ProtocolError::Unexpected { expected: "Proof", got: other.kind().into() }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_secret_is_resolved_from_the_file_then_the_environment_then_the_tls_folder() {
        let dir = tempfile::Builder::new().prefix("pf-secret-").tempdir().unwrap();
        let file = dir.path().join("given");
        std::fs::write(&file, "the secret of the file given").unwrap();
        std::fs::write(dir.path().join(SECRET_FILE), "the secret of the tls folder").unwrap();
        let tls = Some(dir.path());
        // The one test of this process that sets the variable, and it removes it before any other resolve.
        std::env::set_var(SECRET_ENV, "the secret of the environment");
        let from_file = Secret::resolve(Some(&file), tls, false).unwrap();
        let from_env = Secret::resolve(None, tls, false).unwrap();
        std::env::remove_var(SECRET_ENV);
        assert!(from_file.matches(b"the secret of the file given"));
        assert!(from_env.matches(b"the secret of the environment"));
        assert!(Secret::resolve(None, tls, false).unwrap().matches(b"the secret of the tls folder"));
        assert!(matches!(Secret::resolve(None, None, false), Err(SecretError::Missing)));
        assert!(Secret::resolve(None, None, true).unwrap().is_insecure());
        std::fs::write(&file, "short").unwrap();
        assert!(matches!(Secret::resolve(Some(&file), tls, true), Err(SecretError::TooShort(_))));
    }

    #[test]
    fn a_secret_matches_itself_only_and_the_insecure_secret_matches_nothing() {
        let s = Secret::from_bytes(b"0123456789abcdef", "test").unwrap();
        assert!(s.matches(b"0123456789abcdef"));
        assert!(s.matches(b" 0123456789abcdef\n"));
        assert!(!s.matches(b"0123456789abcdeF"));
        assert!(!s.matches(b"0123456789abcde"));
        assert!(!s.matches(b""));
        assert!(!Secret::insecure().matches(b""));
    }
}
