//! Encrypted, mutually authenticated links: TLS 1.3 (rustls with the ring provider) under a job CA that
//! `coordinator keys init DIR` makes. Both ends present a certificate of that CA and accept only a peer with
//! one; the coordinator's certificate names it `photonfarm-coordinator` and the workers'
//! `photonfarm-worker`, so that whichever side dials checks it reached the other role. The shared-secret
//! handshake (`auth`) still runs inside the TLS stream.
//!
//! A key folder holds `ca.pem`, `coordinator.pem` and `coordinator.key`, `worker.pem` and `worker.key`, and
//! a `secret` for the handshake. The CA's private key is not kept: no one can issue another certificate of
//! the job, and a new folder is a new job CA.

use super::auth::{Secret, SECRET_FILE};
use super::connection::Connection;
use super::error::ProtocolError;
use super::message::Role;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpStream;

/// The certificate of the job CA.
pub const CA_FILE: &str = "ca.pem";

/// The DNS name in the certificate of `role`, which the dialling side checks.
fn role_name(role: Role) -> &'static str {
    match role {
        Role::Coordinator => "photonfarm-coordinator",
        Role::Worker => "photonfarm-worker",
    }
}

/// The file stem of `role`'s certificate and key.
fn role_file(role: Role) -> &'static str {
    match role {
        Role::Coordinator => "coordinator",
        Role::Worker => "worker",
    }
}

/// Why keys could not be made, read or used.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    #[error("cannot read {path}: {reason}")]
    Read { path: String, reason: String },
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("{0} already holds keys: give an empty or new folder (a new folder is a new job CA)")]
    Exists(String),
    #[error("cannot make the certificates: {0}")]
    Generate(String),
    #[error("the keys in {dir} do not make a TLS configuration: {reason}")]
    Config { dir: String, reason: String },
}

/// Makes a job CA and a certificate with its key for the coordinator and for the workers in `dir` (created
/// if missing), with a fresh shared secret; refuses a folder that already holds keys. Returns the files
/// written.
pub fn init_keys(dir: &Path) -> Result<Vec<PathBuf>, TlsError> {
    use rcgen::{BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair};
    use rcgen::{KeyUsagePurpose, PKCS_ECDSA_P256_SHA256};
    let names = [CA_FILE, "coordinator.pem", "coordinator.key", "worker.pem", "worker.key", SECRET_FILE];
    if names.iter().any(|n| dir.join(n).exists()) {
        return Err(TlsError::Exists(dir.display().to_string()));
    }
    let generate = |e: rcgen::Error| TlsError::Generate(e.to_string());
    let mut ca = CertificateParams::new(Vec::<String>::new()).map_err(generate)?;
    ca.distinguished_name.push(DnType::CommonName, "photonfarm job CA");
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign, KeyUsagePurpose::DigitalSignature];
    let ca_key = KeyPair::generate_for(&PKCS_ECDSA_P256_SHA256).map_err(generate)?;
    let ca_cert = ca.self_signed(&ca_key).map_err(generate)?;
    let issuer = Issuer::new(ca, ca_key);
    let mut files = vec![(CA_FILE.to_string(), ca_cert.pem(), false)];
    for role in [Role::Coordinator, Role::Worker] {
        let mut params = CertificateParams::new(vec![role_name(role).to_string()]).map_err(generate)?;
        params.distinguished_name.push(DnType::CommonName, role_name(role));
        params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        // Either role may accept the TCP connection (a coordinator's --listen, a worker's serve), so each
        // certificate serves as a server's and as a client's.
        params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth, ExtendedKeyUsagePurpose::ClientAuth];
        let key = KeyPair::generate_for(&PKCS_ECDSA_P256_SHA256).map_err(generate)?;
        let cert = params.signed_by(&key, &issuer).map_err(generate)?;
        files.push((format!("{}.pem", role_file(role)), cert.pem(), false));
        files.push((format!("{}.key", role_file(role)), key.serialize_pem(), true));
    }
    let secret = Secret::random();
    files.push((SECRET_FILE.to_string(), String::from_utf8_lossy(secret.expose_for_child()).into_owned(), true));
    std::fs::create_dir_all(dir).map_err(|source| TlsError::Write { path: dir.display().to_string(), source })?;
    let mut written = Vec::new();
    for (name, text, private) in files {
        let path = dir.join(&name);
        write_file(&path, text.as_bytes(), private)
            .map_err(|source| TlsError::Write { path: path.display().to_string(), source })?;
        written.push(path);
    }
    Ok(written)
}

/// Writes a file; a private one (a key, the secret) readable by its owner only.
fn write_file(path: &Path, bytes: &[u8], private: bool) -> std::io::Result<()> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(if private { 0o600 } else { 0o644 });
    }
    #[cfg(not(unix))]
    let _ = private;
    options.open(path)?.write_all(bytes)
}

/// One end's TLS set-up: its certificate and key, and the job CA it trusts.
#[derive(Clone)]
pub struct Tls {
    role: Role,
    server: Arc<rustls::ServerConfig>,
    client: Arc<rustls::ClientConfig>,
}

impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tls({:?})", self.role)
    }
}

/// How long the TLS handshake may take.
const TLS_HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

impl Tls {
    /// Reads `role`'s certificate and key and the job CA from a folder `keys init` made.
    pub fn load(dir: &Path, role: Role) -> Result<Self, TlsError> {
        let read = |name: &str| -> Result<Vec<u8>, TlsError> {
            let path = dir.join(name);
            std::fs::read(&path).map_err(|e| TlsError::Read { path: path.display().to_string(), reason: e.to_string() })
        };
        let bad = |name: &str, reason: String| TlsError::Read { path: dir.join(name).display().to_string(), reason };
        let ca_pem = read(CA_FILE)?;
        let ca = CertificateDer::from_pem_slice(&ca_pem).map_err(|e| bad(CA_FILE, e.to_string()))?;
        let cert_name = format!("{}.pem", role_file(role));
        let key_name = format!("{}.key", role_file(role));
        let cert = CertificateDer::from_pem_slice(&read(&cert_name)?).map_err(|e| bad(&cert_name, e.to_string()))?;
        let key = PrivateKeyDer::from_pem_slice(&read(&key_name)?).map_err(|e| bad(&key_name, e.to_string()))?;
        let config = |reason: String| TlsError::Config { dir: dir.display().to_string(), reason };
        let mut roots = rustls::RootCertStore::empty();
        roots.add(ca).map_err(|e| config(format!("{CA_FILE}: {e}")))?;
        let roots = Arc::new(roots);
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(roots.clone(), provider.clone())
            .build()
            .map_err(|e| config(e.to_string()))?;
        let server = rustls::ServerConfig::builder_with_provider(provider.clone())
            .with_protocol_versions(&[&rustls::version::TLS13])
            .map_err(|e| config(e.to_string()))?
            .with_client_cert_verifier(verifier)
            .with_single_cert(vec![cert.clone()], key.clone_key())
            .map_err(|e| config(format!("{cert_name} and {key_name}: {e}")))?;
        let client = rustls::ClientConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13])
            .map_err(|e| config(e.to_string()))?
            .with_root_certificates(roots)
            .with_client_auth_cert(vec![cert], key)
            .map_err(|e| config(format!("{cert_name} and {key_name}: {e}")))?;
        Ok(Tls { role, server: Arc::new(server), client: Arc::new(client) })
    }

    /// Runs the TLS handshake as the side that accepted `stream`. A peer that sends something other than a TLS
    /// handshake (a plaintext photonfarm link, a probe) is refused with an error that says so.
    pub async fn accept(&self, stream: TcpStream) -> Result<Connection, ProtocolError> {
        let peer = stream.peer_addr()?;
        stream.set_nodelay(true)?;
        let mut first = [0u8; 1];
        let n = tokio::time::timeout(TLS_HANDSHAKE_TIMEOUT, stream.peek(&mut first))
            .await
            .map_err(|_| ProtocolError::Timeout(TLS_HANDSHAKE_TIMEOUT, "the TLS handshake"))??;
        // Every TLS connection opens with a handshake record (content type 22).
        if n == 1 && first[0] != 22 {
            return Err(ProtocolError::Tls(
                "the peer does not speak TLS (a plaintext link to a TLS port: give it --tls-dir too)".into(),
            ));
        }
        let acceptor = tokio_rustls::TlsAcceptor::from(self.server.clone());
        let tls = tokio::time::timeout(TLS_HANDSHAKE_TIMEOUT, acceptor.accept(stream))
            .await
            .map_err(|_| ProtocolError::Timeout(TLS_HANDSHAKE_TIMEOUT, "the TLS handshake"))?
            .map_err(tls_error)?;
        Ok(Connection::from_stream(tls, peer))
    }

    /// Runs the TLS handshake as the side that dialled `stream`, expecting the other role's certificate.
    pub async fn connect(&self, stream: TcpStream) -> Result<Connection, ProtocolError> {
        let peer = stream.peer_addr()?;
        stream.set_nodelay(true)?;
        let other = match self.role {
            Role::Coordinator => Role::Worker,
            Role::Worker => Role::Coordinator,
        };
        let name = ServerName::try_from(role_name(other)).expect("the role names are valid DNS names");
        let connector = tokio_rustls::TlsConnector::from(self.client.clone());
        let tls = tokio::time::timeout(TLS_HANDSHAKE_TIMEOUT, connector.connect(name, stream))
            .await
            .map_err(|_| ProtocolError::Timeout(TLS_HANDSHAKE_TIMEOUT, "the TLS handshake"))?
            .map_err(tls_error)?;
        Ok(Connection::from_stream(tls, peer))
    }
}

/// The TLS error inside an I/O error, in words.
fn tls_error(e: std::io::Error) -> ProtocolError {
    let text = match e.get_ref().and_then(|inner| inner.downcast_ref::<rustls::Error>()) {
        Some(rustls::Error::InvalidCertificate(c)) => {
            format!("the peer's certificate is refused ({c:?}): it is not of this job's CA")
        }
        Some(rustls::Error::AlertReceived(a)) => {
            format!("the peer refused the TLS handshake ({a:?}): is this end's certificate of the peer's job CA?")
        }
        Some(other) => other.to_string(),
        None => e.to_string(),
    };
    ProtocolError::Tls(text)
}

/// A plaintext link or TLS, chosen by the caller for one listener or one dial.
#[derive(Clone, Debug)]
pub enum Transport {
    Plain,
    Tls(Tls),
}

impl Transport {
    /// The link over an accepted socket.
    pub async fn accept(&self, stream: TcpStream) -> Result<Connection, ProtocolError> {
        match self {
            Transport::Plain => plain_accept(stream).await,
            Transport::Tls(t) => t.accept(stream).await,
        }
    }

    /// The link over a dialled socket.
    pub async fn connect(&self, stream: TcpStream) -> Result<Connection, ProtocolError> {
        match self {
            Transport::Plain => Ok(Connection::new(stream)?),
            Transport::Tls(t) => t.connect(stream).await,
        }
    }

    /// True for TLS.
    pub fn is_tls(&self) -> bool {
        matches!(self, Transport::Tls(_))
    }
}

/// A plaintext link; a peer that opens with a TLS handshake is refused with an error that says so, rather
/// than as a frame of a few hundred megabytes.
async fn plain_accept(stream: TcpStream) -> Result<Connection, ProtocolError> {
    let mut first = [0u8; 3];
    if let Ok(Ok(3)) = tokio::time::timeout(Duration::from_millis(500), stream.peek(&mut first)).await {
        if first[0] == 22 && first[1] == 3 {
            return Err(ProtocolError::Tls(
                "the peer speaks TLS to a plaintext port (give this end --tls-dir too)".into(),
            ));
        }
    }
    Ok(Connection::new(stream)?)
}
