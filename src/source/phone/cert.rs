//! The phone page's certificate: self-signed, made with rcgen on the first start and kept
//! (`phone-cert.pem`, `phone-key.pem`, the key readable by its owner only), served by rustls
//! with the ring provider (no OpenSSL).

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use std::path::Path;
use std::sync::Arc;

/// The certificate file's name.
pub const CERT_FILE: &str = "phone-cert.pem";
/// The private key's file name.
pub const KEY_FILE: &str = "phone-key.pem";

/// A certificate and its key, loaded.
#[derive(Debug)]
pub struct Certificate {
    cert: CertificateDer<'static>,
    key: PrivateKeyDer<'static>,
    /// SHA-256 of the certificate's DER, upper-case hex pairs joined by `:`.
    pub fingerprint: String,
}

impl Certificate {
    /// The certificate kept in `dir`, or a new one made (and kept) there when `dir` holds
    /// none. The error says which file and why.
    pub fn load_or_make(dir: &Path) -> Result<Certificate, String> {
        let (cert_path, key_path) = (dir.join(CERT_FILE), dir.join(KEY_FILE));
        if !cert_path.exists() && !key_path.exists() {
            make(dir)?;
        }
        // Both read (regular files, bounded) before either is parsed.
        let (cert_pem, key_pem) = (
            read_pem(&cert_path, "a certificate")?,
            read_pem(&key_path, "a private key")?,
        );
        let cert = CertificateDer::from_pem_slice(&cert_pem)
            .map_err(|e| format!("{}: {e}", cert_path.display()))?;
        let key = PrivateKeyDer::from_pem_slice(&key_pem)
            .map_err(|e| format!("{}: {e}", key_path.display()))?;
        Ok(Certificate {
            fingerprint: fingerprint(&cert),
            cert,
            key,
        })
    }
}

/// The largest certificate or key file read, bytes (a PEM certificate chain is a few KiB).
pub const MAX_PEM: u64 = 64 * 1024;

/// The bytes of `path`, a regular file of at most [`MAX_PEM`] bytes, checked before it is
/// opened: a FIFO, a device (`/dev/zero`, `/dev/urandom`) or a huge file is an error naming
/// the file at once, never a hang or an allocation of its size.
fn read_pem(path: &Path, what: &str) -> Result<Vec<u8>, String> {
    crate::named_file::read_text(path, MAX_PEM, what)
        .map(String::into_bytes)
        .map_err(|e| format!("{}: {e}", path.display()))
}

impl Certificate {
    /// A rustls server configuration serving it (TLS 1.2 and 1.3, HTTP/1.1).
    pub fn server_config(&self) -> Result<Arc<rustls::ServerConfig>, String> {
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut config = rustls::ServerConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .map_err(|e| e.to_string())?
            .with_no_client_auth()
            .with_single_cert(vec![self.cert.clone()], self.key.clone_key())
            .map_err(|e| format!("the certificate and its key: {e}"))?;
        config.alpn_protocols = vec![b"http/1.1".to_vec()];
        Ok(Arc::new(config))
    }
}

/// Makes a self-signed certificate for `localhost`, this machine's name and its addresses.
fn make(dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut names = vec!["localhost".to_owned(), "127.0.0.1".to_owned()];
    if let Ok(h) = std::fs::read_to_string("/etc/hostname") {
        let h = h.trim();
        if !h.is_empty()
            && h.len() < 254
            && h.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'.')
        {
            names.push(h.to_owned());
        }
    }
    let lan = super::public_host("0.0.0.0:0".parse().expect("an address")).ip();
    if !lan.is_loopback() {
        names.push(lan.to_string());
    }
    let mut params = rcgen::CertificateParams::new(names)
        .map_err(|e| format!("cannot make a certificate: {e}"))?;
    // What Apple and Chrome want of a server certificate, even one accepted by hand: at most
    // 398 days of validity, and the server-authentication purpose.
    let today = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() / 86_400) as i64;
    let ymd = |days: i64| {
        let (y, m, d) = civil_from_days(days);
        rcgen::date_time_ymd(y, m, d)
    };
    params.not_before = ymd(today - 1);
    params.not_after = ymd(today + VALID_DAYS - 1);
    params.extended_key_usages = vec![rcgen::ExtendedKeyUsagePurpose::ServerAuth];
    let signing_key = rcgen::KeyPair::generate().map_err(|e| format!("cannot make a key: {e}"))?;
    let cert = params
        .self_signed(&signing_key)
        .map_err(|e| format!("cannot make a certificate: {e}"))?;
    let made = rcgen::CertifiedKey { cert, signing_key };
    let key_path = dir.join(KEY_FILE);
    write_private(&key_path, made.signing_key.serialize_pem().as_bytes())
        .map_err(|e| format!("{}: {e}", key_path.display()))?;
    let cert_path = dir.join(CERT_FILE);
    crate::atomic::write_atomic(&cert_path, made.cert.pem().as_bytes())
        .map_err(|e| format!("{}: {e}", cert_path.display()))?;
    tracing::info!(path = %cert_path.display(), "made a self-signed certificate for the phone page");
    Ok(())
}

/// Days a new certificate is valid (browsers refuse server certificates valid for longer than
/// 398 days). An expired one is refused by the phone's browser: delete `phone-cert.pem` and
/// `phone-key.pem` and the next start makes a new one.
const VALID_DAYS: i64 = 397;

/// The proleptic Gregorian date of `days` since 1970-01-01 (H. Hinnant's `civil_from_days`).
fn civil_from_days(days: i64) -> (i32, u8, u8) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u8;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u8;
    let y = (yoe + era * 400 + i64::from(m <= 2)) as i32;
    (y, m, d)
}

/// Writes `bytes` to a new file readable by its owner only.
fn write_private(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)?;
    f.write_all(bytes)?;
    f.sync_all()
}

/// SHA-256 of `cert`, as `AB:CD:…`.
pub fn fingerprint(cert: &CertificateDer<'_>) -> String {
    ring::digest::digest(&ring::digest::SHA256, cert.as_ref())
        .as_ref()
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

#[cfg(test)]
mod tests {
    #[test]
    fn dates_from_days() {
        assert_eq!(super::civil_from_days(0), (1970, 1, 1));
        assert_eq!(super::civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(super::civil_from_days(20_790), (2026, 12, 3));
        assert_eq!(super::civil_from_days(-1), (1969, 12, 31));
    }
}
