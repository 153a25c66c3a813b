//! The TCP link's frames as a `tokio-util` codec: [`FrameDecoder`] wraps the protocol's
//! own [`decode_frame`] (its length checks, its total decoding) for [`FramedRead`], which
//! keeps the read buffer and reads until a whole frame is there. The client's and the
//! simulator's read loops both use it ([`frames`], [`next_frame`]).

use std::future::poll_fn;
use std::io;
use std::pin::Pin;

use futures_core::Stream;
use tokio::io::AsyncRead;
use tokio_util::bytes::{Buf, BytesMut};
use tokio_util::codec::{Decoder, FramedRead};

use super::frame::{body_len, decode_frame, Frame};
use super::DecodeError;

/// Why no (further) frame could be read from a link.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The connection failed or closed (also in the middle of a frame).
    #[error("{0}")]
    Io(#[from] io::Error),
    /// The peer sent bytes that are not a frame; the link cannot be read further.
    #[error("{0}")]
    Decode(#[from] DecodeError),
}

/// Decodes whole frames (length field included) from a byte stream.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameDecoder;

impl Decoder for FrameDecoder {
    type Item = Frame;
    type Error = ReadError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Frame>, ReadError> {
        match decode_frame(src)? {
            Some((frame, n)) => {
                src.advance(n);
                Ok(Some(frame))
            }
            None => {
                // Room for the rest of the announced frame (its length is checked already,
                // so at most MAX_FRAME).
                if let Some(&[a, b, c, d]) = src.get(..4) {
                    let want = 4 + body_len([a, b, c, d])?;
                    src.reserve(want.saturating_sub(src.len()));
                }
                Ok(None)
            }
        }
    }
}

/// The frames of a link's read half, read through a 64 KiB buffer.
pub fn frames<R: AsyncRead>(rd: R) -> FramedRead<R, FrameDecoder> {
    FramedRead::with_capacity(rd, FrameDecoder, 64 * 1024)
}

/// The next frame; `None` when the peer closed the link between frames.
pub async fn next_frame<R: AsyncRead + Unpin>(
    frames: &mut FramedRead<R, FrameDecoder>,
) -> Option<Result<Frame, ReadError>> {
    poll_fn(|cx| Pin::new(&mut *frames).poll_next(cx)).await
}
