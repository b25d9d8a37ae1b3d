//! A `Connection` owns the framing of one TCP link (as in tokio's mini-redis): whole messages in and out,
//! with a frame limit and timeouts. It splits into a reader and a writer for links that read and write at
//! once.

use super::frame::{read_frame, write_frame, DEFAULT_MAX_FRAME};
use super::message::{decode, encode, Message};
use super::ProtocolError;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncWriteExt, BufReader, BufWriter};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;

/// Reads whole messages.
pub struct MessageReader {
    inner: BufReader<OwnedReadHalf>,
    max_frame: u32,
    /// Bytes read so far, frames included.
    pub bytes: u64,
}

/// Writes whole messages.
pub struct MessageWriter {
    inner: BufWriter<OwnedWriteHalf>,
    max_frame: u32,
    /// Bytes written so far, frames included.
    pub bytes: u64,
}

/// Both halves of a link.
pub struct Connection {
    pub reader: MessageReader,
    pub writer: MessageWriter,
    pub peer: SocketAddr,
}

impl Connection {
    /// Wraps a connected socket.
    pub fn new(stream: TcpStream) -> std::io::Result<Self> {
        let peer = stream.peer_addr()?;
        stream.set_nodelay(true)?;
        let (r, w) = stream.into_split();
        Ok(Connection {
            reader: MessageReader { inner: BufReader::new(r), max_frame: DEFAULT_MAX_FRAME, bytes: 0 },
            writer: MessageWriter { inner: BufWriter::new(w), max_frame: DEFAULT_MAX_FRAME, bytes: 0 },
            peer,
        })
    }

    /// Sends one message and flushes it.
    pub async fn write(&mut self, message: &Message) -> Result<(), ProtocolError> {
        self.writer.write(message).await
    }

    /// The next message; `Closed` at a clean end of stream.
    pub async fn read(&mut self) -> Result<Message, ProtocolError> {
        self.reader.read().await
    }

    /// The next message within `limit`.
    pub async fn read_within(&mut self, limit: Duration, what: &'static str) -> Result<Message, ProtocolError> {
        self.reader.read_within(limit, what).await
    }

    /// Splits into halves that can be used from different tasks.
    pub fn split(self) -> (MessageReader, MessageWriter) {
        (self.reader, self.writer)
    }
}

impl MessageReader {
    /// The next message; `Closed` at a clean end of stream.
    pub async fn read(&mut self) -> Result<Message, ProtocolError> {
        match read_frame(&mut self.inner, self.max_frame).await? {
            Some(body) => {
                self.bytes += 4 + body.len() as u64;
                decode(&body)
            }
            None => Err(ProtocolError::Closed),
        }
    }

    /// The next message within `limit`. Not cancel-safe across calls: a timeout ends the link.
    pub async fn read_within(&mut self, limit: Duration, what: &'static str) -> Result<Message, ProtocolError> {
        tokio::time::timeout(limit, self.read()).await.map_err(|_| ProtocolError::Timeout(limit, what))?
    }
}

impl MessageWriter {
    /// Sends one message and flushes it.
    pub async fn write(&mut self, message: &Message) -> Result<(), ProtocolError> {
        let body = encode(message)?;
        write_frame(&mut self.inner, &body, self.max_frame).await?;
        self.inner.flush().await?;
        self.bytes += 4 + body.len() as u64;
        Ok(())
    }

    /// Closes the sending direction.
    pub async fn shutdown(&mut self) -> Result<(), ProtocolError> {
        self.inner.shutdown().await?;
        Ok(())
    }
}
