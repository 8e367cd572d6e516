//! A client connection's socket as hyper sees it: the socket, giving
//! hyper's own error answers a JSON body.
//!
//! A request hyper cannot parse (a malformed request line or header, a
//! head over its buffer) is answered by hyper itself, before any service
//! sees it, with an empty 400, 414 or 431. Every other error answer is
//! JSON with a `content-type`, so an error head without one can only be
//! hyper's: it is replaced, as it is written, by the same status with a
//! JSON body.

use super::error::error_body;
use std::io;
use std::pin::Pin;
use std::task::{Context, Poll, ready};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// A socket that gives hyper's own error answers a JSON body.
pub struct ConnIo<S> {
    inner: S,
    /// The answer written in place of hyper's, and how much of it is out.
    replacement: Vec<u8>,
    sent: usize,
}

impl<S> ConnIo<S> {
    /// Wraps `inner`.
    pub fn new(inner: S) -> ConnIo<S> {
        ConnIo {
            inner,
            replacement: Vec::new(),
            sent: 0,
        }
    }
}

impl<S: AsyncWrite + Unpin> ConnIo<S> {
    /// Writes what is left of a replacement answer.
    fn poll_replacement(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while self.sent < self.replacement.len() {
            let n =
                ready!(Pin::new(&mut self.inner).poll_write(cx, &self.replacement[self.sent..]))?;
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            self.sent += n;
        }
        Poll::Ready(Ok(()))
    }

    /// Takes hyper's own error answer at the start of `buf`, if that is
    /// what it holds, and queues its JSON replacement; the bytes taken.
    fn take_automatic(&mut self, buf: &[u8]) -> Option<usize> {
        let (head_len, answer) = json_answer(buf)?;
        self.replacement = answer;
        self.sent = 0;
        Some(head_len)
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for ConnIo<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for ConnIo<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        ready!(this.poll_replacement(cx))?;
        if let Some(n) = this.take_automatic(buf) {
            return Poll::Ready(Ok(n));
        }
        Pin::new(&mut this.inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        ready!(this.poll_replacement(cx))?;
        // hyper writes a head as one slice, ahead of any body.
        if let Some(first) = bufs.iter().find(|b| !b.is_empty())
            && let Some(n) = this.take_automatic(first)
        {
            return Poll::Ready(Ok(n));
        }
        Pin::new(&mut this.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        ready!(this.poll_replacement(cx))?;
        Pin::new(&mut this.inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        ready!(this.poll_replacement(cx))?;
        Pin::new(&mut this.inner).poll_shutdown(cx)
    }
}

/// When `buf` starts with an error head that hyper wrote by itself (a 400,
/// 414 or 431 without a `content-type` and with an empty body), its length
/// and the same answer with a JSON body.
fn json_answer(buf: &[u8]) -> Option<(usize, Vec<u8>)> {
    if !buf.starts_with(b"HTTP/1.") {
        return None;
    }
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n")? + 4;
    let head = std::str::from_utf8(&buf[..end]).ok()?;
    let mut lines = head[..end - 4].split("\r\n");
    let status_line = lines.next()?;
    let status = status_line.split(' ').nth(1)?;
    let (code, message) = match status {
        "400" => (
            "malformed_request",
            "the request is not valid HTTP/1.1: its request line or a header could not be parsed",
        ),
        "414" => ("uri_too_long", "the request target is too long"),
        "431" => (
            "headers_too_large",
            "the request head is over 64 KiB or has over 200 header fields",
        ),
        _ => return None,
    };
    let fields: Vec<&str> = lines.collect();
    let named = |name: &str| {
        fields.iter().any(|f| {
            f.split(':')
                .next()
                .is_some_and(|n| n.trim().eq_ignore_ascii_case(name))
        })
    };
    let empty = fields.iter().any(|f| {
        f.split_once(':').is_some_and(|(n, v)| {
            n.trim().eq_ignore_ascii_case("content-length") && v.trim() == "0"
        })
    });
    if named("content-type") || !empty {
        return None;
    }
    let body = error_body(code, message);
    let mut out = format!("{status_line}\r\ncontent-type: application/json\r\n");
    for f in fields.iter().filter(|f| {
        !f.split(':')
            .next()
            .is_some_and(|n| n.trim().eq_ignore_ascii_case("content-length"))
    }) {
        out.push_str(f);
        out.push_str("\r\n");
    }
    out.push_str(&format!("content-length: {}\r\n\r\n{body}", body.len()));
    Some((end, out.into_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_bare_error_heads_are_replaced() {
        let hyper = b"HTTP/1.1 400 Bad Request\r\nconnection: close\r\ncontent-length: 0\r\ndate: x\r\n\r\n";
        let (n, out) = json_answer(hyper).unwrap();
        assert_eq!(n, hyper.len());
        let text = String::from_utf8(out).unwrap();
        let (head, body) = text.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 400 Bad Request\r\n"), "{head}");
        assert!(head.contains("content-type: application/json"));
        assert!(head.contains("connection: close") && head.contains("date: x"));
        assert!(head.contains(&format!("content-length: {}", body.len())));
        let v: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(v["error"]["code"], "malformed_request");
        let too_large =
            b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\n\r\n";
        assert!(json_answer(too_large).is_some());
        // The server's own answers already have a type, or a body, or are
        // no errors.
        for other in [
            &b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/json\r\ncontent-length: 0\r\n\r\n"[..],
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 12\r\n\r\n",
            b"HTTP/1.1 304 Not Modified\r\ncontent-length: 0\r\n\r\n",
            b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n",
            b"{\"partial\": 1}",
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n",
        ] {
            assert!(json_answer(other).is_none(), "{}", String::from_utf8_lossy(other));
        }
    }
}
