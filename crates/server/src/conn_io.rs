//! A client connection's socket as hyper sees it: the socket, plus the
//! two things the server needs from below hyper.
//!
//! - **When the connection was last active** ([`Clock`]), for the idle
//!   and header timeouts that [`super::listen`] enforces: hyper's own
//!   header timeout starts as soon as a connection waits for a request,
//!   so it cannot tell a keep-alive connection at rest from a client
//!   trickling a request head.
//! - **A JSON body for hyper's own error answers.** A request hyper cannot
//!   parse (a malformed request line or header, a head over its buffer) is
//!   answered by hyper itself, before any service sees it, with an empty
//!   400, 414 or 431. Every other error answer is JSON with a
//!   `content-type`, so an error head without one can only be hyper's:
//!   it is replaced, as it is written, by the same status with a JSON body.

use super::error::error_body;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::task::{Context, Poll, ready};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::sync::Notify;

/// What a connection did lately, shared by its socket, its requests and
/// the task that closes it when it has been quiet too long.
#[derive(Debug)]
pub struct Clock {
    opened: Instant,
    /// Milliseconds after `opened` of its last read or write.
    last_active: AtomicU64,
    /// Milliseconds after `opened`, plus one, at which the first byte of a
    /// request head arrived with no request in flight; 0: none since.
    head_started: AtomicU64,
    /// Requests answered so far.
    answered: AtomicU64,
    /// Requests being answered.
    pub in_flight: AtomicUsize,
    /// Woken when the deadline may have moved earlier.
    pub changed: Notify,
}

impl Clock {
    /// The clock of a connection opened now.
    pub fn new() -> Clock {
        Clock {
            opened: Instant::now(),
            last_active: AtomicU64::new(0),
            head_started: AtomicU64::new(0),
            answered: AtomicU64::new(0),
            in_flight: AtomicUsize::new(0),
            changed: Notify::new(),
        }
    }

    fn now_ms(&self) -> u64 {
        self.opened.elapsed().as_millis() as u64
    }

    fn at(&self, ms: u64) -> Instant {
        self.opened + Duration::from_millis(ms)
    }

    fn touch(&self) {
        self.last_active.store(self.now_ms(), Ordering::Relaxed);
    }

    /// Bytes arrived: with no request in flight they begin a request head.
    fn read_some(&self) {
        self.touch();
        if self.in_flight.load(Ordering::SeqCst) == 0
            && self.head_started.load(Ordering::SeqCst) == 0
        {
            self.head_started.store(self.now_ms() + 1, Ordering::SeqCst);
            self.changed.notify_one();
        }
    }

    /// A request head was read in full and its answer begins.
    pub fn request_started(&self) {
        self.in_flight.fetch_add(1, Ordering::SeqCst);
        self.head_started.store(0, Ordering::SeqCst);
    }

    /// A request's answer was handed to hyper.
    pub fn request_ended(&self) {
        self.touch();
        self.answered.fetch_add(1, Ordering::SeqCst);
        self.in_flight.fetch_sub(1, Ordering::SeqCst);
        self.changed.notify_one();
    }

    /// When the connection is to be closed if nothing happens before:
    /// `header` after the first byte of a request head (or after opening,
    /// for a connection that never sent one), `idle` after the last
    /// activity of a connection at rest between requests; `None` while a
    /// request is in flight.
    pub fn deadline(&self, header: Duration, idle: Duration) -> Option<Instant> {
        if self.in_flight.load(Ordering::SeqCst) > 0 {
            return None;
        }
        let head = self.head_started.load(Ordering::SeqCst);
        Some(if head > 0 {
            self.at(head - 1) + header
        } else if self.answered.load(Ordering::SeqCst) == 0 {
            self.opened + header
        } else {
            self.at(self.last_active.load(Ordering::Relaxed)) + idle
        })
    }
}

impl Default for Clock {
    fn default() -> Clock {
        Clock::new()
    }
}

/// A socket that keeps a connection's [`Clock`] and gives hyper's own
/// error answers a JSON body.
pub struct ConnIo<S> {
    inner: S,
    clock: Arc<Clock>,
    /// The answer written in place of hyper's, and how much of it is out.
    replacement: Vec<u8>,
    sent: usize,
}

impl<S> ConnIo<S> {
    /// Wraps `inner`, reporting its activity to `clock`.
    pub fn new(inner: S, clock: Arc<Clock>) -> ConnIo<S> {
        ConnIo {
            inner,
            clock,
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
            self.clock.touch();
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
        let this = self.get_mut();
        let before = buf.filled().len();
        ready!(Pin::new(&mut this.inner).poll_read(cx, buf))?;
        if buf.filled().len() > before {
            this.clock.read_some();
        }
        Poll::Ready(Ok(()))
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
        let n = ready!(Pin::new(&mut this.inner).poll_write(cx, buf))?;
        this.clock.touch();
        Poll::Ready(Ok(n))
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
        let n = ready!(Pin::new(&mut this.inner).poll_write_vectored(cx, bufs))?;
        this.clock.touch();
        Poll::Ready(Ok(n))
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

    #[test]
    fn deadlines_follow_what_the_connection_does() {
        let (header, idle) = (Duration::from_secs(10), Duration::from_secs(60));
        let c = Clock::new();
        // A fresh connection has the header timeout to send a request.
        assert_eq!(c.deadline(header, idle), Some(c.opened + header));
        c.read_some();
        let head = c.deadline(header, idle).unwrap();
        assert!(head <= Instant::now() + header);
        c.request_started();
        assert_eq!(c.deadline(header, idle), None);
        c.request_ended();
        // At rest between requests: the idle timeout.
        let rest = c.deadline(header, idle).unwrap();
        assert!(rest > Instant::now() + header && rest <= Instant::now() + idle);
        // The next request's first byte brings the header timeout back.
        c.read_some();
        assert!(c.deadline(header, idle).unwrap() <= Instant::now() + header);
    }
}
