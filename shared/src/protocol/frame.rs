//! Length-prefixed frames: a 4-byte big-endian length, then that many bytes. The length is checked against a
//! maximum before anything is allocated, and the body is read as it arrives, so a peer that announces a large
//! frame and sends little costs no more memory than it sent.

use super::error::ProtocolError;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// Default largest frame: a 1920×1080 snapshot with every layer is about 150 MB before compression.
pub const DEFAULT_MAX_FRAME: u32 = 256 << 20;

/// Reads one frame. `Ok(None)` is a clean end of stream between frames.
pub async fn read_frame<R: AsyncRead + Unpin>(reader: &mut R, max: u32) -> Result<Option<Vec<u8>>, ProtocolError> {
    let mut prefix = [0u8; 4];
    let mut got = 0;
    while got < 4 {
        let n = reader.read(&mut prefix[got..]).await?;
        if n == 0 {
            return if got == 0 { Ok(None) } else { Err(ProtocolError::Truncated { expected: 4, got }) };
        }
        got += n;
    }
    let len = u32::from_be_bytes(prefix);
    if len > max {
        return Err(ProtocolError::FrameTooLarge { len, max });
    }
    let mut body = Vec::with_capacity((len as usize).min(64 << 10));
    let read = reader.take(len as u64).read_to_end(&mut body).await?;
    if read < len as usize {
        return Err(ProtocolError::Truncated { expected: len as usize, got: read });
    }
    Ok(Some(body))
}

/// Writes one frame (not flushed).
pub async fn write_frame<W: AsyncWrite + Unpin>(writer: &mut W, body: &[u8], max: u32) -> Result<(), ProtocolError> {
    let len = u32::try_from(body.len())
        .ok()
        .filter(|&l| l <= max)
        .ok_or(ProtocolError::FrameTooLarge { len: body.len().min(u32::MAX as usize) as u32, max })?;
    writer.write_all(&len.to_be_bytes()).await?;
    writer.write_all(body).await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run<F: std::future::Future>(f: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap().block_on(f)
    }

    #[test]
    fn frames_round_trip_in_order() {
        run(async {
            let mut buf = Vec::new();
            write_frame(&mut buf, b"hello", 100).await.unwrap();
            write_frame(&mut buf, b"", 100).await.unwrap();
            let mut r = &buf[..];
            assert_eq!(read_frame(&mut r, 100).await.unwrap().unwrap(), b"hello");
            assert_eq!(read_frame(&mut r, 100).await.unwrap().unwrap(), b"");
            assert!(read_frame(&mut r, 100).await.unwrap().is_none());
        });
    }

    #[test]
    fn an_oversized_length_prefix_is_refused_before_allocating() {
        run(async {
            let bytes = u32::MAX.to_be_bytes();
            let err = read_frame(&mut &bytes[..], 1 << 20).await.unwrap_err();
            assert!(matches!(err, ProtocolError::FrameTooLarge { len: u32::MAX, .. }), "{err}");
        });
    }

    #[test]
    fn a_truncated_frame_is_an_error_not_a_short_message() {
        run(async {
            let mut bytes = 10u32.to_be_bytes().to_vec();
            bytes.extend_from_slice(b"abc");
            let err = read_frame(&mut &bytes[..], 100).await.unwrap_err();
            assert!(matches!(err, ProtocolError::Truncated { expected: 10, got: 3 }), "{err}");
            let err = read_frame(&mut &[0u8, 0][..], 100).await.unwrap_err();
            assert!(matches!(err, ProtocolError::Truncated { expected: 4, got: 2 }), "{err}");
        });
    }
}
