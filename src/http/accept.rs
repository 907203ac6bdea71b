//! The accept loop, with the limits `axum::serve` does not set (issue 30,
//! docs/service.md "Budgets and timeouts"): a client has
//! [`HEADER_READ_TIMEOUT`] to send a request's head (an idle keep-alive
//! connection too: it is waiting for a head), a response write that the
//! client does not read for [`WRITE_STALL`] ends the connection, and one
//! client address holds at most `per_client` connections at once (more
//! are answered 503 and closed). Graceful shutdown as `axum::serve`'s:
//! stop accepting, let open requests finish, then return.

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpListener;

/// Longest a client may take to send a request's head (request line and
/// headers), counted from when the server starts waiting for it.
pub const HEADER_READ_TIMEOUT: Duration = Duration::from_secs(10);
/// Longest a response write may wait for the client to read.
pub const WRITE_STALL: Duration = Duration::from_secs(30);
/// Default connections one client address may hold at once.
pub const PER_CLIENT: usize = 128;

/// Open connections per client address.
#[derive(Default, Clone)]
struct Clients(Arc<Mutex<HashMap<IpAddr, usize>>>);

/// One connection's place in [`Clients`], given back when dropped.
struct Slot {
    clients: Clients,
    ip: IpAddr,
}

impl Clients {
    fn take(&self, ip: IpAddr, cap: usize) -> Option<Slot> {
        let mut m = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let n = m.entry(ip).or_insert(0);
        if *n >= cap {
            return None;
        }
        *n += 1;
        Some(Slot {
            clients: self.clone(),
            ip,
        })
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut m = self.clients.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = m.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                m.remove(&self.ip);
            }
        }
    }
}

/// The answer to a connection over the cap: written once into the fresh
/// socket's empty buffer (it cannot block), then the socket is closed.
fn over_cap_response(cap: usize) -> String {
    let body = format!(
        r#"{{"type":"about:blank","title":"Too many connections","status":503,"detail":"this client holds {cap} connections to the server already: close some, then retry"}}"#
    );
    format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/problem+json\r\nretry-after: 1\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
        body.len()
    )
}

/// Serve `app` on `listener` until `shutdown` resolves, then let open
/// connections finish their requests and return. With `tls`, every
/// connection is a TLS one (HTTPS, and WSS for the agents): its handshake
/// must end within [`HEADER_READ_TIMEOUT`] too.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    per_client: usize,
    tls: Option<tokio_rustls::TlsAcceptor>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) {
    let clients = Clients::default();
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let mut shutdown = std::pin::pin!(shutdown);
    let mut tasks = tokio::task::JoinSet::new();
    loop {
        let (tcp, peer) = tokio::select! {
            r = listener.accept() => match r {
                Ok(c) => c,
                Err(e) => {
                    // Out of descriptors (EMFILE) and the like: wait, not spin.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
            _ = &mut shutdown => break,
        };
        // Finished connections' tasks, reaped as we go.
        while tasks.try_join_next().is_some() {}
        let Some(slot) = clients.take(peer.ip(), per_client) else {
            tracing::warn!(client = %peer.ip(), cap = per_client, "connection refused: too many from this client");
            let _ = tcp.try_write(over_cap_response(per_client).as_bytes());
            continue;
        };
        // No Nagle delay: an agent's small messages (a trial, a result, an
        // ack) would otherwise wait for the peer's delayed ACK, ~40 ms each.
        let _ = tcp.set_nodelay(true);
        let stream = StallLimit::new(tcp, WRITE_STALL);
        let service = TowerToHyperService::new(app.clone());
        let stop = stop_rx.clone();
        let tls = tls.clone();
        tasks.spawn(async move {
            let _slot = slot;
            match tls {
                None => connection(TokioIo::new(stream), service, stop).await,
                Some(acceptor) => {
                    match tokio::time::timeout(HEADER_READ_TIMEOUT, acceptor.accept(stream)).await {
                        Ok(Ok(s)) => connection(TokioIo::new(s), service, stop).await,
                        Ok(Err(e)) => {
                            tracing::debug!(client = %peer.ip(), error = %e, "TLS handshake failed")
                        }
                        Err(_) => {
                            tracing::debug!(client = %peer.ip(), "TLS handshake timed out")
                        }
                    }
                }
            }
        });
    }
    drop(listener);
    let _ = stop_tx.send(true);
    while tasks.join_next().await.is_some() {}
}

/// Serve one connection's requests until it ends, or until `stop` says so
/// (then gracefully: the open request finishes).
async fn connection<IO>(
    io: TokioIo<IO>,
    service: TowerToHyperService<Router>,
    mut stop: tokio::sync::watch::Receiver<bool>,
) where
    IO: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(HEADER_READ_TIMEOUT);
    let io = TokioIo::new(ProblemOnBadHead::new(io.into_inner()));
    let conn = builder.serve_connection(io, service).with_upgrades();
    let mut conn = std::pin::pin!(conn);
    loop {
        tokio::select! {
            r = conn.as_mut() => {
                if let Err(e) = r {
                    tracing::debug!(error = %e, "connection ended");
                }
                break;
            }
            changed = stop.changed(), if !*stop.borrow() => {
                if changed.is_ok() {
                    conn.as_mut().graceful_shutdown();
                }
            }
        }
    }
}

/// The heads hyper writes itself when it cannot read a request's head,
/// before any handler runs (then it closes the connection): the status,
/// and what the problem+json that replaces it says.
const BARE_HEADS: [(&str, u16, &str, &str); 3] = [
    (
        "HTTP/1.1 400 Bad Request\r\nconnection: close\r\ncontent-length: 0\r\n",
        400,
        "Bad Request",
        "the request's head could not be read: a request line or header that is not HTTP/1.1 (a control character in a header, a header without a colon)",
    ),
    (
        "HTTP/1.1 431 Request Header Fields Too Large\r\nconnection: close\r\ncontent-length: 0\r\n",
        431,
        "Request Header Fields Too Large",
        "the request's head is too large: at most 100 headers and about 400 KiB in all",
    ),
    (
        "HTTP/1.1 414 URI Too Long\r\nconnection: close\r\ncontent-length: 0\r\n",
        414,
        "URI Too Long",
        "the request's URI is too long: at most 65534 bytes",
    ),
];

/// The problem+json answer in place of hyper's bare `head`, if it is one.
fn problem_for_bare(head: &[u8]) -> Option<Vec<u8>> {
    if !head.ends_with(b"\r\n\r\n") {
        return None;
    }
    let (_, status, title, detail) = BARE_HEADS
        .iter()
        .find(|(bare, ..)| head.starts_with(bare.as_bytes()))?;
    let body = serde_json::json!({
        "type": "about:blank",
        "title": title,
        "status": status,
        "detail": detail,
    })
    .to_string();
    Some(
        format!(
            "HTTP/1.1 {status} {title}\r\ncontent-type: application/problem+json\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
            body.len()
        )
        .into_bytes(),
    )
}

/// A stream that replaces the bare 400, 431 or 414 hyper writes for a
/// request head it cannot read (a control byte in a header, more than 100
/// headers, a URI past its limit: no handler ever sees those requests)
/// with the same status and a problem+json body, as every other error of
/// the API has (issue 45). Every other write passes through unchanged.
pub struct ProblemOnBadHead<T> {
    io: T,
    /// A replacement still being written, and how much of it is.
    out: Vec<u8>,
    sent: usize,
}

impl<T> ProblemOnBadHead<T> {
    pub fn new(io: T) -> Self {
        Self {
            io,
            out: Vec::new(),
            sent: 0,
        }
    }
}

impl<T: AsyncWrite + Unpin> ProblemOnBadHead<T> {
    /// Write what is left of a replacement.
    fn drain(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while self.sent < self.out.len() {
            match Pin::new(&mut self.io).poll_write(cx, &self.out[self.sent..]) {
                Poll::Ready(Ok(0)) => return Poll::Ready(Err(io::ErrorKind::WriteZero.into())),
                Poll::Ready(Ok(n)) => self.sent += n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return Poll::Pending,
            }
        }
        Poll::Ready(Ok(()))
    }

    /// `buf` taken as written when it is a bare head: its replacement is
    /// queued (and written as far as the socket takes it now).
    fn swap(&mut self, cx: &mut Context<'_>, buf: &[u8]) -> Option<Poll<io::Result<usize>>> {
        let replacement = problem_for_bare(buf)?;
        self.out = replacement;
        self.sent = 0;
        Some(match self.drain(cx) {
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            // Queued: poll_flush and poll_shutdown finish it.
            _ => Poll::Ready(Ok(buf.len())),
        })
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for ProblemOnBadHead<T> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().io).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for ProblemOnBadHead<T> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        std::task::ready!(this.drain(cx))?;
        if let Some(r) = this.swap(cx, buf) {
            return r;
        }
        Pin::new(&mut this.io).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        std::task::ready!(this.drain(cx))?;
        if let Some(first) = bufs.iter().find(|b| !b.is_empty()) {
            if let Some(r) = this.swap(cx, first) {
                return r;
            }
        }
        Pin::new(&mut this.io).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        match this.drain(cx) {
            Poll::Ready(Ok(())) => Pin::new(&mut this.io).poll_flush(cx),
            other => other,
        }
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        match this.drain(cx) {
            Poll::Ready(Ok(())) => Pin::new(&mut this.io).poll_shutdown(cx),
            other => other,
        }
    }
}

/// A stream whose writes fail once one has waited `limit` for the peer to
/// read (its socket's buffers full): a client that never reads cannot
/// hold a connection, a task and a response in memory.
pub struct StallLimit<T> {
    io: T,
    limit: Duration,
    stalled: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl<T> StallLimit<T> {
    pub fn new(io: T, limit: Duration) -> Self {
        Self {
            io,
            limit,
            stalled: None,
        }
    }

    /// `r` from the inner stream; Pending starts (or keeps) the clock, and
    /// past the limit the write is an error.
    fn timed<R>(&mut self, cx: &mut Context<'_>, r: Poll<io::Result<R>>) -> Poll<io::Result<R>> {
        match r {
            Poll::Ready(r) => {
                self.stalled = None;
                Poll::Ready(r)
            }
            Poll::Pending => {
                let limit = self.limit;
                let sleep = self
                    .stalled
                    .get_or_insert_with(|| Box::pin(tokio::time::sleep(limit)));
                if sleep.as_mut().poll(cx).is_ready() {
                    self.stalled = None;
                    return Poll::Ready(Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        format!("the peer read nothing for {} s", limit.as_secs_f64()),
                    )));
                }
                Poll::Pending
            }
        }
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for StallLimit<T> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().io).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for StallLimit<T> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_write(cx, buf);
        this.timed(cx, r)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_write_vectored(cx, bufs);
        this.timed(cx, r)
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_flush(cx);
        this.timed(cx, r)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_shutdown(cx);
        this.timed(cx, r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncWriteExt;
    use tokio::net::TcpStream;

    /// A peer that never reads: the writes fill the socket's buffers, then
    /// the next one fails after the limit (not never).
    #[tokio::test]
    async fn a_write_the_peer_never_reads_fails_after_the_limit() {
        let l = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = l.local_addr().unwrap();
        let _peer = TcpStream::connect(addr).await.unwrap();
        let (server, _) = l.accept().await.unwrap();
        let mut s = StallLimit::new(server, Duration::from_millis(200));
        let chunk = vec![0u8; 64 * 1024];
        let t0 = tokio::time::Instant::now();
        let err = loop {
            if let Err(e) = s.write_all(&chunk).await {
                break e;
            }
            assert!(t0.elapsed() < Duration::from_secs(20), "never failed");
        };
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        assert!(err.to_string().contains("0.2 s"), "{err}");
    }

    /// hyper's own answers to heads it cannot read are problem+json now
    /// (issue 45: a control byte in a header gave an empty 400, 120
    /// headers an empty 431), over a real connection; a good request and
    /// the app's own 404 pass unchanged.
    #[tokio::test]
    async fn a_head_hyper_cannot_read_is_answered_with_problem_json() {
        use tokio::io::AsyncReadExt;
        let l = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = l.local_addr().unwrap();
        let app = Router::new().route("/", axum::routing::get(|| async { "ok" }));
        tokio::spawn(serve(l, app, 8, None, std::future::pending()));
        let ask = |req: Vec<u8>| async move {
            let mut s = TcpStream::connect(addr).await.unwrap();
            s.write_all(&req).await.unwrap();
            let mut out = Vec::new();
            let _ = tokio::time::timeout(Duration::from_secs(10), s.read_to_end(&mut out)).await;
            String::from_utf8_lossy(&out).into_owned()
        };
        let many: String = (0..120).map(|i| format!("x-{i}: 1\r\n")).collect();
        for (req, status) in [
            (
                b"GET / HTTP/1.1\r\nhost: a\r\nx-a: a\x01b\r\n\r\n".to_vec(),
                400,
            ),
            (
                format!("GET / HTTP/1.1\r\nhost: a\r\n{many}\r\n").into_bytes(),
                431,
            ),
            (
                format!("GET /{} HTTP/1.1\r\nhost: a\r\n\r\n", "a".repeat(70_000)).into_bytes(),
                414,
            ),
            (b"GARBAGE\r\n\r\n".to_vec(), 400),
        ] {
            let r = ask(req).await;
            let (head, body) = r.split_once("\r\n\r\n").unwrap_or((&r, ""));
            assert!(head.starts_with(&format!("HTTP/1.1 {status} ")), "{r}");
            assert!(
                head.contains("content-type: application/problem+json"),
                "{r}"
            );
            assert!(
                head.contains(&format!("content-length: {}", body.len())),
                "{r}"
            );
            let v: serde_json::Value = serde_json::from_str(body).unwrap();
            assert_eq!(v["status"], status, "{r}");
            assert!(v["detail"].as_str().is_some_and(|d| !d.is_empty()), "{r}");
        }
        let ok = ask(b"GET / HTTP/1.1\r\nhost: a\r\nconnection: close\r\n\r\n".to_vec()).await;
        assert!(
            ok.starts_with("HTTP/1.1 200 ") && ok.ends_with("\r\n\r\nok"),
            "{ok}"
        );
        let missing =
            ask(b"GET /nope HTTP/1.1\r\nhost: a\r\nconnection: close\r\n\r\n".to_vec()).await;
        assert!(
            missing.starts_with("HTTP/1.1 404 ") && !missing.contains("problem+json"),
            "{missing}"
        );
    }

    /// A writer that takes `per_write` bytes a call, says Pending every
    /// other call (waking at once), or fails every write.
    struct Trickle {
        out: Vec<u8>,
        per_write: usize,
        pending_next: bool,
        fail: bool,
        vectored: bool,
    }

    impl Trickle {
        fn new(per_write: usize) -> Self {
            Self {
                out: Vec::new(),
                per_write,
                pending_next: false,
                fail: false,
                vectored: false,
            }
        }
    }

    impl AsyncWrite for Trickle {
        fn poll_write(
            self: Pin<&mut Self>,
            cx: &mut Context<'_>,
            buf: &[u8],
        ) -> Poll<io::Result<usize>> {
            let this = self.get_mut();
            if this.fail {
                return Poll::Ready(Err(io::ErrorKind::BrokenPipe.into()));
            }
            this.pending_next = !this.pending_next;
            if this.pending_next {
                cx.waker().wake_by_ref();
                return Poll::Pending;
            }
            let n = buf.len().min(this.per_write);
            this.out.extend_from_slice(&buf[..n]);
            Poll::Ready(Ok(n))
        }
        fn is_write_vectored(&self) -> bool {
            self.vectored
        }
        fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
            Poll::Ready(Ok(()))
        }
        fn poll_shutdown(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
            Poll::Ready(Ok(()))
        }
    }

    const BARE: &[u8] =
        b"HTTP/1.1 431 Request Header Fields Too Large\r\nconnection: close\r\ncontent-length: 0\r\ndate: x\r\n\r\n";

    /// Through `poll_write` onto a socket that takes 7 bytes at a time and
    /// is often not ready: the whole replacement arrives, by the flush or
    /// by the shutdown that ends the connection; other bytes pass as they
    /// are; a failing socket's error is the write's.
    #[tokio::test]
    async fn the_replacement_is_written_whole_onto_a_slow_socket() {
        let want = problem_for_bare(BARE).unwrap();
        for end_by_shutdown in [false, true] {
            let mut w = ProblemOnBadHead::new(Trickle::new(7));
            w.write_all(BARE).await.unwrap();
            if end_by_shutdown {
                w.shutdown().await.unwrap();
            } else {
                w.flush().await.unwrap();
            }
            assert_eq!(w.io.out, want, "shutdown {end_by_shutdown}");
        }
        let mut w = ProblemOnBadHead::new(Trickle::new(7));
        w.write_all(b"HTTP/1.1 200 OK\r\n\r\nok").await.unwrap();
        w.flush().await.unwrap();
        assert_eq!(w.io.out, b"HTTP/1.1 200 OK\r\n\r\nok");
        let mut broken = Trickle::new(7);
        broken.fail = true;
        let mut w = ProblemOnBadHead::new(broken);
        let e = w.write_all(BARE).await.unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::BrokenPipe);
        for vectored in [false, true] {
            let mut t = Trickle::new(7);
            t.vectored = vectored;
            assert_eq!(ProblemOnBadHead::new(t).is_write_vectored(), vectored);
        }
    }

    /// Only hyper's bare heads are replaced: an app's 400 with a body, or
    /// a head cut short, is not.
    #[test]
    fn only_a_whole_bare_head_is_replaced() {
        let bare = b"HTTP/1.1 400 Bad Request\r\nconnection: close\r\ncontent-length: 0\r\ndate: x\r\n\r\n";
        assert!(problem_for_bare(bare).is_some());
        assert!(problem_for_bare(&bare[..bare.len() - 2]).is_none());
        let app = b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/problem+json\r\ncontent-length: 2\r\n\r\n";
        assert!(problem_for_bare(app).is_none());
    }

    /// The cap counts per address and gives slots back.
    #[test]
    fn a_client_holds_at_most_its_cap() {
        let c = Clients::default();
        let ip: IpAddr = "127.0.0.1".parse().unwrap();
        let other: IpAddr = "127.0.0.2".parse().unwrap();
        let a = c.take(ip, 2).unwrap();
        let _b = c.take(ip, 2).unwrap();
        assert!(c.take(ip, 2).is_none());
        assert!(c.take(other, 2).is_some());
        drop(a);
        assert!(c.take(ip, 2).is_some());
        let r = over_cap_response(2);
        let (head, body) = r.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 503"));
        assert!(head.contains(&format!("content-length: {}", body.len())));
        let v: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(v["status"], 503);
    }
}
