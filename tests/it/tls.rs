//! TLS end to end (issue 45 item 3): `serve --tls-cert/--tls-key` serves
//! HTTPS and WSS; the CLI client and the agent trust a CA given by file or
//! `ZWIDTH_CA_FILE`; a client that does not trust the server's certificate
//! is refused. The CA and the server's certificate are made here (rcgen),
//! for `localhost` and 127.0.0.1.

use crate::common::*;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A CA and a server certificate signed by it, as PEM files in `dir`:
/// (ca.pem, server.pem, server.key).
fn certificates(dir: &std::path::Path) -> [std::path::PathBuf; 3] {
    use rcgen::{
        BasicConstraints, CertificateParams, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
        KeyUsagePurpose,
    };
    let mut ca = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    let ca_key = KeyPair::generate().unwrap();
    let ca_pem = ca.self_signed(&ca_key).unwrap().pem();
    let issuer = Issuer::new(ca, ca_key);
    let mut leaf = CertificateParams::new(vec!["localhost".into(), "127.0.0.1".into()]).unwrap();
    leaf.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth];
    let key = KeyPair::generate().unwrap();
    let cert_pem = leaf.signed_by(&key, &issuer).unwrap().pem();
    let paths = [
        dir.join("ca.pem"),
        dir.join("server.pem"),
        dir.join("server.key"),
    ];
    std::fs::write(&paths[0], ca_pem).unwrap();
    std::fs::write(&paths[1], cert_pem).unwrap();
    std::fs::write(&paths[2], key.serialize_pem()).unwrap();
    paths
}

fn fresh_dir() -> std::path::PathBuf {
    let dir =
        std::env::temp_dir().join(format!("zwidth-tls-{}-{}", std::process::id(), uuid_like()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// An HTTP client trusting only `ca` (none: trusting nothing).
fn client(ca: Option<&std::path::Path>) -> ureq::Agent {
    let mut roots = rustls::RootCertStore::empty();
    if let Some(ca) = ca {
        use rustls::pki_types::pem::PemObject;
        for c in rustls::pki_types::CertificateDer::pem_file_iter(ca).unwrap() {
            roots.add(c.unwrap()).unwrap();
        }
    }
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let cfg = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    ureq::AgentBuilder::new().tls_config(Arc::new(cfg)).build()
}

/// `zwidth ARGS` with `env`: (exit code, stdout, stderr).
fn zwidth(args: &[&str], env: &[(&str, &std::path::Path)]) -> (i32, String, String) {
    let mut c = Command::new(bin());
    c.args(args)
        .env_remove("ZWIDTH_CA_FILE")
        .env_remove("ZWIDTH_SERVER")
        .stdin(Stdio::null());
    for (k, v) in env {
        c.env(k, v);
    }
    let out = c.output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn https_and_wss_with_a_ca_the_clients_are_given() {
    let dir = fresh_dir();
    let [ca, cert, key] = certificates(&dir);
    let (cert_s, key_s) = (cert.to_str().unwrap(), key.to_str().unwrap());
    let s = start_with(
        dir.clone(),
        &[
            "--rigs",
            "sim:1,bench:attached",
            "--tls-cert",
            cert_s,
            "--tls-key",
            key_s,
        ],
    );
    assert!(s.base.starts_with("https://127.0.0.1:"), "{}", s.base);
    // A client trusting the CA reads over HTTPS, by IP and by name.
    let health = format!("{}/healthz", s.base);
    let r = client(Some(&ca)).get(&health).call().unwrap();
    assert_eq!(r.status(), 200);
    let by_name = health.replace("127.0.0.1", "localhost");
    assert_eq!(
        client(Some(&ca)).get(&by_name).call().unwrap().status(),
        200
    );
    // One that does not trust it is refused by its own TLS check …
    let e = client(None).get(&health).call().unwrap_err().to_string();
    assert!(
        e.contains("UnknownIssuer") || e.contains("certificate"),
        "{e}"
    );
    // … and plain HTTP on the TLS port gets no HTTP answer.
    let plain = health.replace("https://", "http://");
    assert!(ureq::get(&plain)
        .timeout(Duration::from_secs(15))
        .call()
        .is_err());

    // The CLI client: ZWIDTH_CA_FILE makes the server trusted.
    let token = dir.join("test.db.token");
    let body = dir.join("map.json");
    std::fs::write(
        &body,
        r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0]}"#,
    )
    .unwrap();
    let submit = ["submit", body.to_str().unwrap(), "--server", &s.base];
    let env = [
        ("ZWIDTH_TOKEN_FILE", token.as_path()),
        ("ZWIDTH_CA_FILE", &ca),
    ];
    let (code, out, err) = zwidth(&submit, &env);
    assert_eq!(code, 0, "{err}");
    // `submit` prints "<id> <state>".
    let id = out
        .split_whitespace()
        .next()
        .unwrap_or_default()
        .to_string();
    assert!(!id.is_empty());
    let (code, out, err) = zwidth(&["watch", &id, "--server", &s.base], &env);
    assert_eq!(code, 0, "{out}{err}");
    // Without the CA: the system's roots do not know this one (exit 1, a
    // failure to reach the server, not bad input).
    let (code, _, err) = zwidth(&submit, &env[..1]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("cannot reach"), "{err}");
    // A CA file that is not one: exit 2 naming it.
    let (code, _, err) = zwidth(&submit, &[env[0], ("ZWIDTH_CA_FILE", &token)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("ZWIDTH_CA_FILE") && err.contains("no certificate"),
        "{err}"
    );

    // The agent over WSS with --ca-file: connected, and its rig runs a map.
    let agent_err = dir.join("agent.err");
    let mut agent = Command::new(bin())
        .args(["agent", "--sim", "--rig", "bench", "--server", &s.base])
        .arg("--ca-file")
        .arg(&ca)
        .arg("--token-file")
        .arg(dir.join("test.db.agent-token"))
        .arg("--outbox")
        .arg(dir.join("bench.outbox"))
        .env_remove("ZWIDTH_CA_FILE")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&agent_err).unwrap())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    let connected = || std::fs::read_to_string(&agent_err).unwrap_or_default();
    while !connected().contains("connected to wss://") && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let log = connected();
    assert!(log.contains("connected to wss://127.0.0.1:"), "{log}");
    // Trials go out and results come back over it: a map on the rig
    // (wall hits at draft, as tests/it/agents.rs's) succeeds.
    let https = client(Some(&ca));
    let token = std::fs::read_to_string(&token).unwrap();
    let map = r#"{"kind":"map","scene":{"device":{"coulomb":0.05,"quantization":1e-6,"force_limit":8},"loop":{"sample_hz":2000,"render_hz":1000}},"method":"time","criterion":"stability","b":[0,2],"accuracy":"draft"}"#;
    let r: serde_json::Value = https
        .post(&format!("{}/v1/experiments?rig=bench", s.base))
        .set("authorization", &format!("Bearer {}", token.trim()))
        .set("content-type", "application/json")
        .send_string(map)
        .unwrap()
        .into_json()
        .unwrap();
    let url = format!("{}/v1/experiments/{}", s.base, r["id"].as_str().unwrap());
    let deadline = Instant::now() + Duration::from_secs(60);
    let state = loop {
        let v: serde_json::Value = https.get(&url).call().unwrap().into_json().unwrap();
        let state = v["state"].as_str().unwrap_or_default().to_string();
        if !["queued", "running"].contains(&state.as_str()) || Instant::now() > deadline {
            break state;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = agent.kill();
    let _ = agent.wait();
    assert_eq!(state, "succeeded", "{}", connected());
    // A server that is neither http:// nor https://: exit 2 naming --server.
    let (code, _, err) = zwidth(
        &[
            "agent",
            "--sim",
            "--rig",
            "bench",
            "--server",
            "ftp://127.0.0.1:1",
        ],
        &[],
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--server") && err.contains("https://"),
        "{err}"
    );
}

#[test]
fn bad_certificate_files_refuse_the_start_naming_the_flag() {
    let dir = fresh_dir();
    let [_, cert, key] = certificates(&dir);
    let db = dir.join("t.db");
    let serve = |cert: &std::path::Path, key: &std::path::Path| {
        zwidth(
            &[
                "serve",
                "--bind",
                "127.0.0.1:0",
                "--db",
                db.to_str().unwrap(),
                "--tls-cert",
                cert.to_str().unwrap(),
                "--tls-key",
                key.to_str().unwrap(),
            ],
            &[],
        )
    };
    // The key where the certificate goes, and the other way round.
    let (code, _, err) = serve(&key, &key);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--tls-cert") && err.contains("no certificate"),
        "{err}"
    );
    let (code, _, err) = serve(&cert, &cert);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--tls-key"), "{err}");
    // A key that is not the certificate's.
    let other = fresh_dir();
    let [_, _, other_key] = certificates(&other);
    let (code, _, err) = serve(&cert, &other_key);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("does not fit"), "{err}");
    let missing = dir.join("missing.pem");
    let (code, _, err) = serve(&missing, &key);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--tls-cert") && err.contains("missing.pem"),
        "{err}"
    );
    // One without the other (clap's usage error, exit 2).
    let (code, _, err) = zwidth(
        &[
            "serve",
            "--db",
            db.to_str().unwrap(),
            "--tls-cert",
            cert.to_str().unwrap(),
        ],
        &[],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--tls-key"), "{err}");
    // Nothing was started or stored.
    assert!(!db.exists());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&other);
}
