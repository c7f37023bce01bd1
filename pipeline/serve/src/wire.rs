//! The connection under the HTTP server, so that even the answers hyper writes on its own are
//! JSON.
//!
//! When a request cannot be parsed (a URI over 65534 bytes, headers over hyper's buffer, a
//! malformed request line), hyper answers `414`, `431` or `400` itself, with an empty body,
//! before any handler or middleware runs, and closes the connection. Such an answer is the last
//! thing written on its connection, a head with `content-length: 0`; [`JsonErrors`] wraps each
//! connection and replaces that head with the same status carrying `{"error": "..."}`. Every
//! other byte passes through unchanged.

use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, ready};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

/// The statuses hyper answers by itself, with what the JSON says.
const OWN_ANSWERS: [(u16, &str); 3] = [
    (
        400,
        "malformed HTTP request: the request line or a header does not parse",
    ),
    (
        414,
        "URI too long: the server reads URIs of at most 65534 bytes",
    ),
    (431, "request headers too large"),
];

/// Longest head hyper writes for its own answers (status line, `connection`, `content-length`,
/// `date`).
const MAX_OWN_HEAD: usize = 256;

/// A listener whose connections turn hyper's own error answers into JSON.
#[derive(Debug)]
pub(crate) struct JsonErrors {
    inner: TcpListener,
}

impl JsonErrors {
    pub(crate) fn new(inner: TcpListener) -> JsonErrors {
        JsonErrors { inner }
    }
}

impl axum::serve::Listener for JsonErrors {
    type Io = Connection<TcpStream>;
    type Addr = std::net::SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        // axum's accept loop: retries, backing off on errors such as too many open files.
        let (stream, addr) = axum::serve::Listener::accept(&mut self.inner).await;
        (Connection::new(stream), addr)
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

/// How many bytes a connection has written, and what is kept until it has written so many: an
/// answer's heavy-read turn is held until the answer has left, not merely been handed to the HTTP
/// server's buffer (`serve::snapshot`).
#[derive(Default)]
pub(crate) struct Written {
    bytes: AtomicU64,
    kept: Mutex<Vec<(u64, Box<dyn Send>)>>,
    /// The body waiting for the connection to write more before it hands over more.
    waiting: Mutex<Option<std::task::Waker>>,
}

impl std::fmt::Debug for Written {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Written({})", self.bytes())
    }
}

impl Written {
    /// Bytes written so far.
    pub(crate) fn bytes(&self) -> u64 {
        self.bytes.load(Ordering::Acquire)
    }

    /// Keeps `guard` until `mark` bytes in all are written, or the connection is gone.
    pub(crate) fn keep_until(&self, mark: u64, guard: Box<dyn Send>) {
        let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        // Read under the lock that `advance` takes after counting: no mark is passed unseen.
        if self.bytes() < mark {
            kept.push((mark, guard));
        }
    }

    /// True once `mark` bytes in all are written; otherwise `cx` is woken when more are.
    pub(crate) fn reached(&self, mark: u64, cx: &Context<'_>) -> bool {
        if self.bytes() >= mark {
            return true;
        }
        *self.waiting.lock().unwrap_or_else(|e| e.into_inner()) = Some(cx.waker().clone());
        // Written meanwhile: its wake-up may have found no waker yet.
        self.bytes() >= mark
    }

    fn advance(&self, n: usize) {
        let now = self.bytes.fetch_add(n as u64, Ordering::AcqRel) + n as u64;
        {
            let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
            if !kept.is_empty() {
                kept.retain(|(mark, _)| *mark > now);
            }
        }
        let waiting = self
            .waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(waker) = waiting {
            waker.wake();
        }
    }

    #[cfg(test)]
    pub(crate) fn advance_for_test(&self, n: usize) {
        self.advance(n);
    }

    fn release_all(&self) {
        self.kept.lock().unwrap_or_else(|e| e.into_inner()).clear();
        let waiting = self
            .waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        drop(waiting);
    }
}

/// What a request knows of its connection ([`axum::extract::ConnectInfo`]): how far it has
/// written.
#[derive(Debug, Clone)]
pub(crate) struct ConnectionWrites(pub(crate) Arc<Written>);

impl axum::extract::connect_info::Connected<axum::serve::IncomingStream<'_, JsonErrors>>
    for ConnectionWrites
{
    fn connect_info(stream: axum::serve::IncomingStream<'_, JsonErrors>) -> Self {
        ConnectionWrites(stream.io().written.clone())
    }
}

/// One connection: reads pass through; writes pass through unless they end with one of hyper's
/// own error heads, which is replaced.
#[derive(Debug)]
pub(crate) struct Connection<T> {
    inner: T,
    /// Replacement bytes not yet written, and how many of them are.
    pending: Vec<u8>,
    sent: usize,
    /// Bytes taken from the server so far.
    written: Arc<Written>,
}

impl<T> Connection<T> {
    pub(crate) fn new(inner: T) -> Connection<T> {
        Connection {
            inner,
            pending: Vec::new(),
            sent: 0,
            written: Arc::default(),
        }
    }
}

impl<T> Drop for Connection<T> {
    fn drop(&mut self) {
        // Nothing more will be written: what waited for it is let go.
        self.written.release_all();
    }
}

impl<T: AsyncWrite + Unpin> Connection<T> {
    /// Writes what is pending; ready once nothing is.
    fn poll_pending(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while self.sent < self.pending.len() {
            let n = ready!(Pin::new(&mut self.inner).poll_write(cx, &self.pending[self.sent..]))?;
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            self.sent += n;
        }
        self.pending.clear();
        self.sent = 0;
        Poll::Ready(Ok(()))
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for Connection<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for Connection<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        ready!(self.poll_pending(cx))?;
        if let Some(replaced) = replace_own_answer(buf) {
            self.pending = replaced;
            self.sent = 0;
            // Taken whole: the replacement goes out on this and the next calls.
            let _ = self.poll_pending(cx)?;
            self.written.advance(buf.len());
            return Poll::Ready(Ok(buf.len()));
        }
        let n = ready!(Pin::new(&mut self.inner).poll_write(cx, buf))?;
        self.written.advance(n);
        Poll::Ready(Ok(n))
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.poll_pending(cx))?;
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.poll_pending(cx))?;
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }

    // One buffer per write, so a head always arrives whole in `poll_write`.
    fn is_write_vectored(&self) -> bool {
        false
    }
}

/// `buf` with hyper's own error head at its end replaced by a JSON answer, or `None` when it
/// does not end with one.
fn replace_own_answer(buf: &[u8]) -> Option<Vec<u8>> {
    if !buf.ends_with(b"\r\n\r\n") {
        return None;
    }
    let tail_start = buf.len().saturating_sub(MAX_OWN_HEAD);
    let tail = &buf[tail_start..];
    let at = tail
        .windows(9)
        .rposition(|w| w == b"HTTP/1.1 " || w == b"HTTP/1.0 ")?;
    let head = std::str::from_utf8(&tail[at..]).ok()?;
    let mut lines = head.split("\r\n");
    let status_line = lines.next()?;
    let code: u16 = status_line.get(9..12)?.parse().ok()?;
    let (_, message) = OWN_ANSWERS.iter().find(|(c, _)| *c == code)?;
    // Exactly hyper's form: `connection: close`, an empty body and a date, nothing else.
    let mut empty = false;
    let mut date = None;
    for line in lines.filter(|l| !l.is_empty()) {
        let (name, value) = line.split_once(':')?;
        match name.trim().to_ascii_lowercase().as_str() {
            "content-length" if value.trim() == "0" => empty = true,
            "connection" if value.trim().eq_ignore_ascii_case("close") => {}
            "date" => date = Some(value.trim()),
            _ => return None,
        }
    }
    if !empty {
        return None;
    }
    let body = serde_json::json!({ "error": message }).to_string();
    let mut out = buf[..tail_start + at].to_vec();
    out.extend_from_slice(status_line.as_bytes());
    out.extend_from_slice(b"\r\ncontent-type: application/json\r\nconnection: close\r\n");
    if let Some(date) = date {
        out.extend_from_slice(format!("date: {date}\r\n").as_bytes());
    }
    out.extend_from_slice(format!("content-length: {}\r\n\r\n{body}", body.len()).as_bytes());
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DATE: &str = "date: Sat, 02 May 2026 10:00:00 GMT";

    #[test]
    fn hypers_empty_error_heads_become_json() {
        // What hyper 1 writes, byte for byte.
        let head = format!(
            "HTTP/1.1 414 URI Too Long\r\nconnection: close\r\ncontent-length: 0\r\n{DATE}\r\n\r\n"
        );
        let out = String::from_utf8(replace_own_answer(head.as_bytes()).unwrap()).unwrap();
        let (top, body) = out.split_once("\r\n\r\n").unwrap();
        assert!(top.starts_with("HTTP/1.1 414 URI Too Long\r\n"), "{out}");
        assert!(top.contains("content-type: application/json"), "{out}");
        assert!(top.contains(DATE), "{out}");
        assert!(
            top.contains(&format!("content-length: {}", body.len())),
            "{out}"
        );
        let json: serde_json::Value = serde_json::from_str(body).unwrap();
        assert!(json["error"].as_str().unwrap().contains("URI too long"));

        // After an earlier answer on the same connection, only the error head is replaced.
        let earlier = "HTTP/1.1 200 OK\r\ncontent-length: 2\r\n\r\n{}";
        let both = format!(
            "{earlier}{}",
            head.replace("414 URI Too Long", "431 Request Header Fields Too Large")
        );
        let out = String::from_utf8(replace_own_answer(both.as_bytes()).unwrap()).unwrap();
        assert!(out.starts_with(&format!("{earlier}HTTP/1.1 431 ")), "{out}");
        assert!(
            out.ends_with(r#"{"error":"request headers too large"}"#),
            "{out}"
        );
    }

    #[test]
    fn what_waits_for_a_written_mark_is_kept_until_the_connection_passes_it() {
        use std::sync::atomic::AtomicBool;
        struct Flag(Arc<AtomicBool>);
        impl Drop for Flag {
            fn drop(&mut self) {
                self.0.store(true, Ordering::SeqCst);
            }
        }
        let written = Written::default();
        let (first, second) = (Arc::new(AtomicBool::new(false)), Arc::default());
        written.keep_until(100, Box::new(Flag(first.clone())));
        written.keep_until(300, Box::new(Flag(Arc::clone(&second))));
        written.advance(99);
        assert!(!first.load(Ordering::SeqCst));
        written.advance(1);
        assert!(first.load(Ordering::SeqCst) && !second.load(Ordering::SeqCst));
        // A mark already passed lets go at once; a closed connection lets everything go.
        let third = Arc::new(AtomicBool::new(false));
        written.keep_until(50, Box::new(Flag(third.clone())));
        assert!(third.load(Ordering::SeqCst));
        written.release_all();
        assert!(second.load(Ordering::SeqCst));
    }

    #[test]
    fn everything_else_passes_through() {
        for text in [
            "HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n".to_string(),
            format!("HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\nx-other: 1\r\n{DATE}\r\n\r\n"),
            format!("HTTP/1.1 400 Bad Request\r\ncontent-length: 12\r\n{DATE}\r\n\r\n"),
            "HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\n{\"a\":1}".to_string(),
            "{\"log\": [\"HTTP/1.1 414 URI Too Long\"]}".to_string(),
        ] {
            assert_eq!(replace_own_answer(text.as_bytes()), None, "{text}");
        }
    }
}
