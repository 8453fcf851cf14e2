//! The monitoring metrics over HTTP, in the Prometheus text exposition format, for a
//! scraper: `GET /metrics` (any path is answered the same). Off unless `[monitor] http_port`
//! is set; bound to 127.0.0.1 unless `http_address` says otherwise. A minimal HTTP/1.0
//! responder on tokio: one short response per connection, never blocking the pipeline.

use crate::shutdown::Shutdown;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The latest exposition text, shared between the monitor and the server.
pub type Exposition = Arc<Mutex<String>>;

/// Binds `addr`: done before a session captures a byte, so that a taken port stops it while
/// its directory is untouched (a retry with the same `--session` then works).
pub async fn bind(addr: SocketAddr) -> std::io::Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(addr).await
}

/// Serves `text` on `listener` (from [`bind`]) until `shutdown`.
pub fn serve(
    listener: tokio::net::TcpListener,
    text: Exposition,
    shutdown: Shutdown,
) -> tokio::task::JoinHandle<()> {
    if let Ok(addr) = listener.local_addr() {
        tracing::info!("monitor: metrics at http://{addr}/metrics");
    }
    tokio::spawn(async move {
        loop {
            let conn = tokio::select! {
                c = listener.accept() => c,
                _ = shutdown.triggered() => break,
            };
            let mut stream = match conn {
                Ok((s, _)) => s,
                Err(e) => {
                    // Out of descriptors, say: do not spin on it.
                    tracing::debug!("monitor: metrics endpoint: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                    continue;
                }
            };
            let body = text.lock().map(|t| t.clone()).unwrap_or_default();
            tokio::spawn(async move {
                // Read (and ignore) the request head, then answer and close.
                let mut buf = [0u8; 1024];
                let _ =
                    tokio::time::timeout(std::time::Duration::from_secs(2), stream.read(&mut buf))
                        .await;
                let head = format!(
                    "HTTP/1.0 200 OK\r\nContent-Type: text/plain; version=0.0.4\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                    body.len()
                );
                // A client that does not read is dropped after a while.
                let _ = tokio::time::timeout(std::time::Duration::from_secs(5), async {
                    stream.write_all(head.as_bytes()).await?;
                    stream.write_all(body.as_bytes()).await?;
                    stream.shutdown().await
                })
                .await;
            });
        }
    })
}
