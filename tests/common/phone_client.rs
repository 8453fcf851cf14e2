//! A client of the phone port of the test's own: TLS by rustls pinned to the session's
//! certificate (what the operator checks by its fingerprint), from any loopback address (other
//! addresses of 127.0.0.0/8 stand in for other hosts), HTTP by hand, WebSockets by
//! tokio-tungstenite.

use super::phone::Daemon;
use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use rustls::{DigitallySignedStruct, SignatureScheme};
use std::net::IpAddr;
use std::sync::Arc;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The phone's own address in these tests.
pub const LOCAL: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);

/// A TCP connection to the port on 127.0.0.1 from the loopback address `from`.
pub async fn tcp_from(from: IpAddr, port: u16) -> std::io::Result<tokio::net::TcpStream> {
    let s = tokio::net::TcpSocket::new_v4()?;
    s.bind(std::net::SocketAddr::new(from, 0))?;
    let tcp = s.connect(([127, 0, 0, 1], port).into()).await?;
    tcp.set_nodelay(true)?;
    Ok(tcp)
}

/// Accepts exactly one certificate: the session's (what the operator checks by fingerprint).
#[derive(Debug)]
pub struct Pinned {
    cert: Vec<u8>,
    provider: Arc<rustls::crypto::CryptoProvider>,
}

impl ServerCertVerifier for Pinned {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        _: &[CertificateDer<'_>],
        _: &ServerName<'_>,
        _: &[u8],
        _: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        if end_entity.as_ref() == self.cert.as_slice() {
            Ok(ServerCertVerified::assertion())
        } else {
            Err(rustls::Error::General(
                "not the session's certificate".into(),
            ))
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.provider
            .signature_verification_algorithms
            .supported_schemes()
    }
}

pub struct Client {
    pub tls: tokio_rustls::TlsConnector,
    pub port: u16,
}

pub type Tls = tokio_rustls::client::TlsStream<tokio::net::TcpStream>;

impl Client {
    pub fn of(d: &Daemon) -> Client {
        let cert = CertificateDer::from_pem_file(d.dir.join("phone-cert.pem")).unwrap();
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let config = rustls::ClientConfig::builder_with_provider(provider.clone())
            .with_safe_default_protocol_versions()
            .unwrap()
            .dangerous()
            .with_custom_certificate_verifier(Arc::new(Pinned {
                cert: cert.to_vec(),
                provider,
            }))
            .with_no_client_auth();
        Client {
            tls: tokio_rustls::TlsConnector::from(Arc::new(config)),
            port: d.port,
        }
    }

    pub async fn connect(&self) -> Tls {
        self.connect_from(LOCAL).await.unwrap()
    }

    /// A TLS connection from the loopback address `from` (another host, for the port).
    pub async fn connect_from(&self, from: IpAddr) -> std::io::Result<Tls> {
        let tcp = tcp_from(from, self.port).await?;
        self.tls
            .connect(ServerName::try_from("localhost").unwrap(), tcp)
            .await
    }

    /// `GET path`: the status and the whole answer.
    pub async fn get(&self, path: &str) -> (u16, String) {
        self.get_from(LOCAL, path).await.unwrap()
    }

    /// `GET path` from the loopback address `from`: the status and the whole answer.
    pub async fn get_from(&self, from: IpAddr, path: &str) -> std::io::Result<(u16, String)> {
        let mut s = self.connect_from(from).await?;
        let req = format!(
            "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nConnection: close\r\n\r\n",
            self.port
        );
        s.write_all(req.as_bytes()).await?;
        let mut bytes = Vec::new();
        let _ = s.read_to_end(&mut bytes).await;
        let text = String::from_utf8_lossy(&bytes).into_owned();
        Ok((super::http_status(&text), text))
    }

    /// The WebSocket at `/phone/ws?token=…`: the socket, or the refusal's status.
    pub async fn ws(&self, token: &str) -> Result<tokio_tungstenite::WebSocketStream<Tls>, u16> {
        self.ws_from(LOCAL, &format!("token={token}"), None).await
    }

    /// The WebSocket at `/phone/ws?QUERY` from `from`, with a `User-Agent` if given.
    pub async fn ws_from(
        &self,
        from: IpAddr,
        query: &str,
        agent: Option<&str>,
    ) -> Result<tokio_tungstenite::WebSocketStream<Tls>, u16> {
        use tokio_tungstenite::tungstenite::client::IntoClientRequest;
        let url = format!("wss://127.0.0.1:{}/phone/ws?{query}", self.port);
        let mut req = url.into_client_request().unwrap();
        if let Some(a) = agent {
            req.headers_mut()
                .insert("user-agent", a.parse().expect("a header value"));
        }
        let tls = self.connect_from(from).await.map_err(|_| 0u16)?;
        match tokio_tungstenite::client_async(req, tls).await {
            Ok((ws, _)) => Ok(ws),
            Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
            Err(_) => Err(0),
        }
    }
}

/// A phone's first frames: HELLO and `n` samples.
pub fn frames(n: u32) -> Vec<u8> {
    use device_protocol::*;
    let mut out = Vec::new();
    Packet::Hello(Hello {
        proto: 1,
        kind: DeviceKind::Phone,
        device_id: 7,
        firmware: 1,
        rate_hz: 60,
        acc_scale: 0.0024,
        gyro_scale: 0.001,
        mag_scale: 0.15,
        ticks_per_rev: 0,
        wheel_circumference_um: 0,
        sensors: 1,
    })
    .encode(0, &mut out);
    for i in 0..n {
        Packet::PhoneSample(PhoneSample {
            t_us: 1000 + i * 16_667,
            acc: [0, 0, 4096],
            gyro: [0; 3],
            mag: [0, 140, -287],
        })
        .encode((i + 1) as u8, &mut out);
    }
    out
}
