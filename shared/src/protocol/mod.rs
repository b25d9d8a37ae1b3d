//! The coordinator–worker protocol (docs/distribution.md, "Protocol"): length-prefixed frames, one message enum encoded with bincode,
//! a handshake that checks the protocol version and proves a shared secret both ways, and snapshots that carry
//! only completed phases, as exact deltas of the sums (`accumulation::delta`); links that leave the machine run
//! inside mutually authenticated TLS (`tls`).

pub mod auth;
pub mod connection;
pub mod error;
pub mod frame;
pub mod message;
pub mod tls;

pub use auth::Secret;
pub use connection::{Connection, MessageReader, MessageWriter};
pub use error::ProtocolError;
pub use message::{
    EngineSpec, FilePiece, FileRef, Job, LitPixels, Message, RayMapPortion, RayMapRequest, Role, Share, Snapshot,
    WorkerInfo, FILE_PIECE_BYTES, PROTOCOL_VERSION,
};
