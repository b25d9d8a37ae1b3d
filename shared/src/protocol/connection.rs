//! A `Connection` owns the framing of one link (as in tokio's mini-redis): whole messages in and out, with a
//! frame limit and timeouts, over plain TCP or TLS (`protocol::tls`). It splits into a reader and a writer for
//! links that read and write at once.

use super::error::ProtocolError;
use super::frame::{read_frame, write_frame, DEFAULT_MAX_FRAME};
use super::message::{decode, encode, Message};
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, BufReader, BufWriter};
use tokio::net::TcpStream;

/// The reading half of a link's stream, whatever carries it.
type ReadHalf = Box<dyn AsyncRead + Send + Unpin>;
/// The writing half of a link's stream.
type WriteHalf = Box<dyn AsyncWrite + Send + Unpin>;

/// Messages read by `MessageReader::forward`, each with the bytes of its frame.
pub type Incoming = tokio::sync::mpsc::UnboundedReceiver<(Result<Message, ProtocolError>, u64)>;

/// Reads whole messages.
pub struct MessageReader {
    inner: BufReader<ReadHalf>,
    max_frame: u32,
    /// Bytes read so far, frames included.
    pub bytes: u64,
}

/// Writes whole messages.
pub struct MessageWriter {
    inner: BufWriter<WriteHalf>,
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
    /// Wraps a connected socket (a plain link).
    pub fn new(stream: TcpStream) -> std::io::Result<Self> {
        let peer = stream.peer_addr()?;
        stream.set_nodelay(true)?;
        let (r, w) = stream.into_split();
        Ok(Self::from_halves(Box::new(r), Box::new(w), peer))
    }

    /// Wraps any stream to `peer`, e.g. a TLS session over a socket.
    pub fn from_stream<S: AsyncRead + AsyncWrite + Send + 'static>(stream: S, peer: SocketAddr) -> Self {
        let (r, w) = tokio::io::split(stream);
        Self::from_halves(Box::new(r), Box::new(w), peer)
    }

    fn from_halves(r: ReadHalf, w: WriteHalf, peer: SocketAddr) -> Self {
        Connection {
            reader: MessageReader { inner: BufReader::new(r), max_frame: DEFAULT_MAX_FRAME, bytes: 0 },
            writer: MessageWriter { inner: BufWriter::new(w), max_frame: DEFAULT_MAX_FRAME, bytes: 0 },
            peer,
        }
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

    /// Reads messages on a task of its own and hands each over with its frame's size, so that a link can wait
    /// for messages and other events at once (reading is not cancel-safe). The stream ends after the first
    /// error; abort the task to stop reading earlier.
    pub fn forward(mut self) -> (Incoming, tokio::task::JoinHandle<()>) {
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        let task = tokio::spawn(async move {
            loop {
                let before = self.bytes;
                let m = self.read().await;
                let end = m.is_err();
                if tx.send((m, self.bytes - before)).is_err() || end {
                    break;
                }
            }
        });
        (rx, task)
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
