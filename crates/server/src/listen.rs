//! Accepting connections: HTTP/1.1 through hyper with a header timeout, an
//! idle timeout, and a cap on open connections.
//!
//! Without limits, idle sockets pile up until the process runs out of file
//! descriptors and health checks time out. Here every connection must send
//! a complete request head within the header timeout of its first byte (or
//! of opening, for its first request), a keep-alive connection at rest
//! between requests is closed after the idle timeout, and at most
//! `max_connections` are open: a new connection over the cap closes the
//! oldest idle one, so that fresh clients (health checks first) get
//! through; when every connection has a request in flight, the newcomer is
//! answered 503 with `Retry-After`. Requests hyper cannot parse get its
//! own answer with a JSON body (see [`super::conn_io`]).

use super::conn_io::{Clock, ConnIo};
use super::error::error_body;
use super::metrics::Metrics;
use axum::Router;
use axum::body::Body;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use parking_lot::Mutex;
use std::collections::BTreeMap;
use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;
use tower::ServiceExt;

/// Per-connection limits.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Time to receive a complete request head, from its first byte (from
    /// opening, for a connection's first request).
    pub header_timeout: Duration,
    /// Time a keep-alive connection may rest between requests.
    pub idle_timeout: Duration,
    /// Open connections at most.
    pub max_connections: usize,
    /// Largest request head hyper buffers, bytes.
    pub max_head_bytes: usize,
    /// Most header fields hyper parses.
    pub max_headers: usize,
}

/// Open files kept besides connections: the listener, the data
/// directory's files, the runtime's own.
pub const SPARE_DESCRIPTORS: u64 = 64;

/// How many of `max_connections` fit in the process's limit on open files,
/// after raising its soft limit towards the hard one if needed. A cap above
/// the limit would let idle sockets exhaust the descriptors before the cap
/// is reached, which is what the cap is there to prevent.
pub fn fit_descriptor_limit(max_connections: usize) -> usize {
    #[cfg(unix)]
    {
        use rustix::process::{Resource, Rlimit, getrlimit, setrlimit};
        let want = u64::try_from(max_connections)
            .unwrap_or(u64::MAX)
            .saturating_add(SPARE_DESCRIPTORS);
        let limit = getrlimit(Resource::Nofile);
        // None: unlimited.
        let mut soft = limit.current.unwrap_or(u64::MAX);
        if soft < want {
            let raised = want.min(limit.maximum.unwrap_or(u64::MAX));
            let set = setrlimit(
                Resource::Nofile,
                Rlimit {
                    current: Some(raised),
                    maximum: limit.maximum,
                },
            );
            if set.is_ok() {
                soft = raised;
            }
        }
        let fit = usize::try_from(soft.saturating_sub(SPARE_DESCRIPTORS))
            .unwrap_or(usize::MAX)
            .max(1);
        if fit < max_connections {
            tracing::warn!(
                max_connections,
                open_files_limit = soft,
                lowered_to = fit,
                "the connection cap does not fit in the open-file limit; lowered"
            );
            return fit;
        }
    }
    max_connections
}

/// One open connection.
struct Conn {
    /// What it is doing (requests in flight among it).
    clock: Arc<Clock>,
    /// Asks its task to close it gracefully.
    close: Arc<Notify>,
    /// Already asked to close.
    closing: bool,
}

/// The open connections, by age (ids increase).
#[derive(Default)]
struct Conns {
    map: Mutex<BTreeMap<u64, Conn>>,
}

enum Admission {
    Admitted(u64, Arc<Clock>, Arc<Notify>),
    Refused,
}

impl Conns {
    /// Admits a connection, closing the oldest idle one when at the cap.
    fn admit(&self, id: u64, max: usize, metrics: &Metrics) -> Admission {
        let mut map = self.map.lock();
        // Connections already closing do not count: an idle one closes at
        // once, a busy one as soon as its response is sent.
        let open = map.values().filter(|c| !c.closing).count();
        if open >= max {
            let oldest_idle = map
                .values_mut()
                .find(|c| !c.closing && c.clock.in_flight.load(Ordering::SeqCst) == 0);
            match oldest_idle {
                Some(c) => {
                    c.closing = true;
                    c.close.notify_one();
                    metrics.connections_evicted.inc();
                }
                None => return Admission::Refused,
            }
        }
        let clock = Arc::new(Clock::new());
        let close = Arc::new(Notify::new());
        map.insert(
            id,
            Conn {
                clock: clock.clone(),
                close: close.clone(),
                closing: false,
            },
        );
        Admission::Admitted(id, clock, close)
    }

    fn remove(&self, id: u64) {
        self.map.lock().remove(&id);
    }

    fn close_all(&self) {
        for c in self.map.lock().values_mut() {
            c.closing = true;
            c.close.notify_one();
        }
    }
}

/// Counts a request in flight on its connection while it lives.
struct Busy(Arc<Clock>);

impl Busy {
    fn new(clock: &Arc<Clock>) -> Busy {
        clock.request_started();
        Busy(clock.clone())
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.request_ended();
    }
}

/// What ends [`serve`]: any future, boxed.
pub type Shutdown = std::pin::Pin<Box<dyn Future<Output = ()> + Send + 'static>>;

/// Serves `app` on `listener` until `shutdown` resolves, then stops
/// accepting, closes idle connections, and returns once the requests in
/// flight have been answered.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: Limits,
    metrics: Arc<Metrics>,
    mut shutdown: Shutdown,
) {
    let conns = Arc::new(Conns::default());
    let mut http = hyper::server::conn::http1::Builder::new();
    // hyper's header timeout would also end connections at rest; both
    // timeouts are kept below instead.
    http.timer(TokioTimer::new())
        .header_read_timeout(None)
        .max_buf_size(limits.max_head_bytes)
        .max_headers(limits.max_headers);
    // Every connection task holds a receiver; `closed` resolves once all
    // are gone.
    let (done_tx, done_rx) = tokio::sync::watch::channel(());
    let mut next_id = 0u64;
    let lingering = Arc::new(tokio::sync::Semaphore::new(REFUSALS_LINGERING));
    loop {
        let stream = tokio::select! {
            _ = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    if !is_connection_error(&e) {
                        // Out of file descriptors or the like: wait
                        // rather than spin; open connections go on.
                        tracing::error!(error = %e, "accept failed");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                    }
                    continue;
                }
            },
        };
        next_id += 1;
        let (id, clock, close) = match conns.admit(next_id, limits.max_connections, &metrics) {
            Admission::Admitted(id, n, c) => (id, n, c),
            Admission::Refused => {
                metrics.connections_refused.inc();
                refuse(stream, &lingering);
                continue;
            }
        };
        metrics.connections_open.inc();
        let app = app.clone();
        let in_flight = clock.clone();
        let service = hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
            let busy = Busy::new(&in_flight);
            let answer = app.clone().oneshot(req.map(Body::new));
            async move {
                let res = answer.await;
                drop(busy);
                res
            }
        });
        let io = ConnIo::new(stream, clock.clone());
        let conn = http.serve_connection(TokioIo::new(io), service);
        let conns = conns.clone();
        let metrics = metrics.clone();
        let done = done_rx.clone();
        tokio::spawn(async move {
            {
                // Dropped before `done`: once `serve` returns, no
                // connection holds the application (and its data
                // directory) any more.
                let mut conn = std::pin::pin!(conn);
                let mut closing = false;
                loop {
                    let deadline = clock.deadline(limits.header_timeout, limits.idle_timeout);
                    let expiry = tokio::time::sleep_until(
                        deadline.map_or_else(far_future, tokio::time::Instant::from_std),
                    );
                    tokio::select! {
                        r = conn.as_mut() => {
                            if let Err(e) = r {
                                tracing::debug!(error = %e, "connection ended with an error");
                            }
                            break;
                        }
                        _ = close.notified(), if !closing => {
                            closing = true;
                            conn.as_mut().graceful_shutdown();
                        }
                        // Activity may have moved the deadline earlier.
                        _ = clock.changed.notified() => {}
                        _ = expiry, if deadline.is_some() => {
                            // Later activity moves it later: look again.
                            let now = std::time::Instant::now();
                            let due = clock.deadline(limits.header_timeout, limits.idle_timeout);
                            if due.is_some_and(|d| d <= now) {
                                tracing::debug!("connection closed after its header or idle timeout");
                                break;
                            }
                        }
                    }
                }
            }
            conns.remove(id);
            metrics.connections_open.dec();
            drop(done);
        });
    }
    drop(listener);
    conns.close_all();
    drop(done_rx);
    done_tx.closed().await;
}

/// A time no connection waits for.
fn far_future() -> tokio::time::Instant {
    tokio::time::Instant::now() + Duration::from_secs(86400 * 365)
}

/// Refused connections still being closed gracefully at most.
const REFUSALS_LINGERING: usize = 64;
/// How long a refused connection may take to be closed gracefully.
const REFUSAL_LINGER: Duration = Duration::from_secs(1);

/// Answers a connection over the cap with 503 and closes it. Closing a
/// socket with unread request bytes resets it, and the reset can destroy
/// the answer before the client reads it; so the answer is followed by a
/// FIN and what the client sent is read off first, for at most
/// [`REFUSAL_LINGER`], by at most [`REFUSALS_LINGERING`] tasks at once.
/// Beyond that the answer is written without waiting and the socket
/// closed at once.
fn refuse(mut stream: TcpStream, lingering: &Arc<tokio::sync::Semaphore>) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let body = error_body("overloaded", "too many open connections; retry later");
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: 1\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
        body.len()
    );
    let Ok(permit) = lingering.clone().try_acquire_owned() else {
        let _ = stream.try_write(answer.as_bytes());
        return;
    };
    tokio::spawn(async move {
        let _permit = permit;
        let _ = tokio::time::timeout(REFUSAL_LINGER, async {
            stream.write_all(answer.as_bytes()).await?;
            stream.shutdown().await?;
            let mut buf = [0u8; 4096];
            let mut left = 64usize << 10;
            while left > 0 {
                let n = stream.read(&mut buf).await?;
                if n == 0 {
                    break;
                }
                left = left.saturating_sub(n);
            }
            Ok::<_, std::io::Error>(())
        })
        .await;
    });
}

/// Errors of one connection that say nothing about the listener.
fn is_connection_error(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::*;
    matches!(
        e.kind(),
        ConnectionRefused | ConnectionAborted | ConnectionReset
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_fits_in_the_open_file_limit() {
        assert_eq!(fit_descriptor_limit(8), 8);
        let most = fit_descriptor_limit(usize::MAX);
        assert!((1..usize::MAX).contains(&most));
    }
}
