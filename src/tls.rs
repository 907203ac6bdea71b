//! TLS configuration, one place for every side (issue 45): the server's
//! certificate (`serve --tls-cert/--tls-key`) and the clients' trust (the
//! system's roots plus an optional CA file: `--ca-file` or
//! `ZWIDTH_CA_FILE`), used by the agent (`wss://`), the CLI client
//! (`https://`) and the service benchmark. rustls with ring, no OpenSSL;
//! every config names its provider, so no process-wide default is needed.
//! PostgreSQL's TLS is sqlx's own (`sslmode`, `sslrootcert` in the URL).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::crypto::CryptoProvider;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use rustls::{ClientConfig, RootCertStore, ServerConfig};

/// The environment variable naming a CA file the clients trust besides
/// the system's roots.
pub const CA_FILE_ENV: &str = "ZWIDTH_CA_FILE";

/// ring, named explicitly in every config.
#[allow(deprecated)] // rustls 0.23.48 deprecates it for lacking post-quantum key exchange
fn ring() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// The server's files: a PEM certificate chain (leaf first) and its PEM
/// private key (PKCS#8, PKCS#1 or SEC1).
#[derive(Debug, Clone, PartialEq)]
pub struct ServerFiles {
    pub cert: PathBuf,
    pub key: PathBuf,
}

/// The certificate chain in `path` (`field` names it in errors).
fn certificates(field: &str, path: &Path) -> Result<Vec<CertificateDer<'static>>, String> {
    let shown = path.display();
    let certs: Vec<_> = CertificateDer::pem_file_iter(path)
        .map_err(|e| format!("{field} {shown}: cannot read a PEM certificate: {e}"))?
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{field} {shown}: not a PEM certificate: {e}"))?;
    if certs.is_empty() {
        return Err(format!(
            "{field} {shown}: no certificate in it (expected PEM blocks \
             \"-----BEGIN CERTIFICATE-----\")"
        ));
    }
    Ok(certs)
}

/// The server's TLS config from its files; an error names the flag.
pub fn server_config(files: &ServerFiles) -> Result<Arc<ServerConfig>, String> {
    let chain = certificates("--tls-cert", &files.cert)?;
    let key = PrivateKeyDer::from_pem_file(&files.key).map_err(|e| {
        format!(
            "--tls-key {}: not a PEM private key (PKCS#8, PKCS#1 or SEC1): {e}",
            files.key.display()
        )
    })?;
    let mut cfg = ServerConfig::builder_with_provider(ring())
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_no_client_auth()
        .with_single_cert(chain, key)
        .map_err(|e| {
            format!(
                "--tls-key {} does not fit --tls-cert {}: {e}",
                files.key.display(),
                files.cert.display()
            )
        })?;
    // HTTP/1.1 only (WebSocket upgrades ride on it).
    cfg.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Arc::new(cfg))
}

/// The CA file from `flag` if given, else from `ZWIDTH_CA_FILE` (empty:
/// none).
pub fn ca_file(flag: Option<PathBuf>) -> Option<PathBuf> {
    flag.or_else(|| {
        std::env::var_os(CA_FILE_ENV)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    })
}

/// The clients' TLS config: the system's roots, plus every certificate in
/// `ca` (a lab's own CA, or a self-signed server's certificate).
pub fn client_config(ca: Option<&Path>) -> Result<Arc<ClientConfig>, String> {
    let mut roots = RootCertStore::empty();
    // Unreadable system stores are skipped: a CA file may be all there is.
    let native = rustls_native_certs::load_native_certs();
    roots.add_parsable_certificates(native.certs);
    if let Some(ca) = ca {
        let field = format!("--ca-file (or {CA_FILE_ENV})");
        for c in certificates(&field, ca)? {
            roots
                .add(c)
                .map_err(|e| format!("{field} {}: not a CA certificate: {e}", ca.display()))?;
        }
    }
    let cfg = ClientConfig::builder_with_provider(ring())
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(Arc::new(cfg))
}

/// A blocking HTTP client trusting `ca` besides the system's roots.
pub fn http_agent(ca: Option<&Path>) -> Result<ureq::Agent, String> {
    Ok(ureq::AgentBuilder::new()
        .tls_config(client_config(ca)?)
        .build())
}
