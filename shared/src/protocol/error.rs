//! The error type every part of the protocol returns.

/// Why a peer or a frame was refused, or the link failed.
#[derive(Debug, thiserror::Error)]
pub enum ProtocolError {
    #[error("connection error: {0}")]
    Io(#[from] std::io::Error),
    #[error("frame of {len} bytes exceeds the limit of {max} bytes")]
    FrameTooLarge { len: u32, max: u32 },
    #[error("truncated frame: expected {expected} bytes, got {got}")]
    Truncated { expected: usize, got: usize },
    #[error("malformed message: {0}")]
    Malformed(String),
    #[error("the peer speaks protocol version {theirs}, this program speaks {ours}")]
    Version { ours: u32, theirs: u32 },
    #[error("authentication failed: the peer does not know the shared secret (or one side runs --insecure)")]
    Authentication,
    #[error("the peer refused: {0}")]
    Refused(String),
    #[error("unexpected message: expected {expected}, got {got}")]
    Unexpected { expected: &'static str, got: String },
    #[error("the peer closed the connection")]
    Closed,
    #[error("TLS: {0}")]
    Tls(String),
    #[error("timed out after {0:?} waiting for {1}")]
    Timeout(std::time::Duration, &'static str),
}
