//! The coordinator–worker protocol (DESIGN §3): length-prefixed frames, one message enum encoded with bincode,
//! a handshake that checks the protocol version and proves a shared secret both ways, and snapshots that carry
//! only completed phases, as exact deltas.

pub mod auth;
pub mod connection;
pub mod frame;
pub mod message;
pub mod snapshot;

pub use auth::Secret;
pub use connection::{Connection, MessageReader, MessageWriter};
pub use message::{EngineSpec, FileRef, Job, Message, Role, Snapshot, WorkerInfo};

/// Bumped whenever a message changes shape; peers with another version are refused in the handshake.
/// 5: the totals count the light paths counted against photon maps.
pub const PROTOCOL_VERSION: u32 = 5;

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
    #[error("timed out after {0:?} waiting for {1}")]
    Timeout(std::time::Duration, &'static str),
    #[error("bad snapshot: {0}")]
    Snapshot(String),
}
