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
