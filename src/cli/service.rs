//! The service and its client: serve, submit, status, watch, results,
//! openapi, backup.

use std::io::Write;

use super::common::*;
use super::{CliError, Command};

pub(super) fn run(command: Command, stdout: &mut impl Write) -> Result<(), CliError> {
    match command {
        Command::Serve {
            db,
            bind,
            tokens,
            token_file,
            allow_origins,
            rigs,
            agent_token_file,
            agent_token,
            agent_heartbeat_ms,
            agent_ttl_ms,
            agent_grace_ms,
            request_timeout_s,
            max_connections_per_client,
            api_only,
            lease_ms,
            tls_cert,
            tls_key,
            reads,
            hosts,
        } => {
            let agent_tokens = secrets(
                agent_token,
                agent_token_file.as_deref(),
                "--agent-token-file",
            )?;
            let lease = crate::rig::lease::Timing {
                heartbeat_ms: agent_heartbeat_ms,
                ttl_ms: agent_ttl_ms,
                grace_ms: agent_grace_ms,
            };
            if !(10..=60_000).contains(&agent_heartbeat_ms)
                || agent_ttl_ms < 2 * agent_heartbeat_ms
                || agent_ttl_ms > 600_000
                || agent_grace_ms > 3_600_000
            {
                return Err(CliError::Input(format!(
                    "--agent-heartbeat-ms = {agent_heartbeat_ms}, --agent-ttl-ms = {agent_ttl_ms}, --agent-grace-ms = {agent_grace_ms}: the heartbeat must be 10 to 60000 ms, the TTL at least two heartbeats and at most 600000 ms, the grace at most 3600000 ms"
                )));
            }
            let tokens = secrets(tokens, token_file.as_deref(), "--token-file")?;
            let rigs = crate::rig::parse_list(&rigs)
                .map_err(|e| CliError::Input(format!("--rigs: {e}")))?;
            let db = db_location(&db)?;
            check_lease_ms(lease_ms)?;
            if !(1..=100_000).contains(&max_connections_per_client) {
                return Err(CliError::Input(format!(
                    "--max-connections-per-client = {max_connections_per_client}: must be 1 to 100000"
                )));
            }
            if api_only && db.sqlite_path().is_some() {
                return Err(CliError::Input(format!(
                    "--api-only with --db {db}: a SQLite database is served by one process, which runs its experiments itself; give a postgres:// URL to run workers apart"
                )));
            }
            // Read before anything starts: a bad file is bad input (exit 2).
            let tls = match (tls_cert, tls_key) {
                (Some(cert), Some(key)) => Some(
                    crate::tls::server_config(&crate::tls::ServerFiles { cert, key })
                        .map_err(CliError::Input)?,
                ),
                _ => None,
            };
            init_logs();
            let rt = runtime()?;
            let hosts: Vec<String> = hosts
                .iter()
                .map(|h| h.trim().to_string())
                .filter(|h| !h.is_empty())
                .collect();
            if let Some(bad) = hosts.iter().find(|h| {
                !h.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.')
            }) {
                return Err(CliError::Input(format!(
                    "--host {bad:?}: a host name (letters, digits, '-' and '.'), without a scheme or port"
                )));
            }
            rt.block_on(crate::http::serve(crate::http::ServeConfig {
                tls,
                private_reads: reads.map(|r| r == "private"),
                hosts,
                db,
                bind,
                tokens,
                agent_tokens,
                allow_origins,
                rigs,
                lease,
                request_timeout_s,
                max_connections_per_client,
                api_only,
                worker: crate::jobs::Worker::new(lease_ms),
            }))
            .map_err(|e| {
                if e.starts_with("refusing") {
                    CliError::Input(e)
                } else {
                    CliError::Failure(e)
                }
            })
        }
        Command::Worker { db, rigs, lease_ms } => {
            let db = db_location(&db)?;
            if db.sqlite_path().is_some() {
                return Err(CliError::Input(format!(
                    "--db {db}: zwidth worker needs a PostgreSQL database (postgres://…); with SQLite, `zwidth serve` runs the experiments itself"
                )));
            }
            check_lease_ms(lease_ms)?;
            let rigs = crate::rig::parse_list(&rigs)
                .map_err(|e| CliError::Input(format!("--rigs: {e}")))?;
            if let Some(r) = rigs.iter().find(|r| r.attached().is_some()) {
                return Err(CliError::Input(format!(
                    "--rigs {}:attached: an attached rig runs in the `zwidth serve` process its agent connects to, not in a worker",
                    r.info().id
                )));
            }
            init_logs();
            let rt = runtime()?;
            rt.block_on(crate::jobs::worker::run(
                db,
                rigs,
                crate::jobs::Worker::new(lease_ms),
            ))
            .map_err(|e| match e {
                crate::store::OpenError::Refused(m) => CliError::Input(m),
                crate::store::OpenError::Failed(m) => CliError::Failure(m),
            })
        }
        command @ Command::Agent { .. } => super::agent::run(command),
        Command::Submit {
            file,
            server,
            priority,
            idempotency_key,
            rig,
            json,
        } => {
            let body = std::fs::read_to_string(&file)
                .map_err(|e| CliError::Input(format!("{} cannot be read: {e}", file.display())))?;
            let v = client(server)?.submit(
                &body,
                priority,
                idempotency_key.as_deref(),
                rig.as_deref(),
            )?;
            if json {
                write_json(stdout, &v)
            } else {
                writeln!(
                    stdout,
                    "{} {}",
                    v["id"].as_str().unwrap_or("?"),
                    v["state"].as_str().unwrap_or("?")
                )
                .map_err(io)
            }
        }
        Command::Openapi { agent_protocol } => {
            let doc = if agent_protocol {
                crate::rig::protocol::schema_json()
            } else {
                crate::http::openapi_json()
            };
            writeln!(stdout, "{doc}").map_err(io)
        }
        Command::Backup { db, out } => {
            // `sqlite://PATH` names the same file as PATH.
            let db = match crate::store::Location::parse(&db.to_string_lossy()) {
                Ok(crate::store::Location::Sqlite(path)) => path,
                Ok(pg) => {
                    return Err(CliError::Input(format!(
                        "--db {pg}: backup copies a SQLite file; a PostgreSQL database is copied with pg_dump"
                    )))
                }
                Err(e) => return Err(CliError::Input(e)),
            };
            if !db.is_file() {
                return Err(CliError::Input(format!(
                    "--db {} is not a database file",
                    db.display()
                )));
            }
            if out.exists() {
                return Err(CliError::Input(format!(
                    "--out {} exists: give a new file",
                    out.display()
                )));
            }
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
            rt.block_on(async {
                let store = crate::store::Store::open(&db)
                    .await
                    .map_err(|e| CliError::Failure(format!("cannot open {}: {e}", db.display())))?;
                let r = store.backup(&out).await;
                let _ = store.close().await;
                r.map_err(|e| CliError::Failure(format!("backup to {} failed: {e}", out.display())))
            })?;
            writeln!(stdout, "{} -> {}", db.display(), out.display()).map_err(io)
        }
        Command::Rig {
            action: super::command::RigCommand::Token { id, server, out },
        } => {
            crate::rig::check_id("ID", &id).map_err(|e| CliError::Input(e.to_string()))?;
            let out = out.unwrap_or_else(|| format!("{id}.agent-token").into());
            let to_stdout = out.as_os_str() == "-";
            // Refused before the server is asked (a credential issued and
            // not written would lock the rig's agent out).
            if !to_stdout && std::fs::symlink_metadata(&out).is_ok() {
                return Err(CliError::Input(format!(
                    "--out {}: exists; remove it or name another file (a credential file is never overwritten)",
                    out.display()
                )));
            }
            let v = client(server)?.agent_token(&id)?;
            let secret = v["agent_token"].as_str().unwrap_or_default();
            if to_stdout {
                return writeln!(stdout, "{secret}").map_err(io);
            }
            crate::http::put_secret(&out, true, secret).map_err(|e| {
                CliError::Failure(format!(
                    "the credential was issued but {} cannot be written ({e}): run `zwidth rig token {id}` again",
                    out.display()
                ))
            })?;
            writeln!(
                stdout,
                "rig {id}: a new agent credential in {} (owner-only); give it to the rig's agent (--token-file)",
                out.display()
            )
            .map_err(io)
        }
        Command::Status { id, server } => write_json(stdout, &client(server)?.status(&id)?),
        Command::Watch { id, server } => {
            let v = client(server)?.watch(&id)?;
            let state = v["state"].as_str().unwrap_or("?").to_string();
            writeln!(stdout, "{id} {state}").map_err(io)?;
            if state == "succeeded" {
                Ok(())
            } else {
                Err(CliError::Failure(format!(
                    "experiment {id} ended {state}: {}",
                    v["error"].as_str().unwrap_or("")
                )))
            }
        }
        Command::Results {
            id,
            server,
            csv,
            svg,
        } => {
            let c = client(server)?;
            let v = c.status(&id)?;
            if v["state"] != "succeeded" {
                return Err(CliError::Input(format!(
                    "experiment {id} is {}, not succeeded: no result yet",
                    v["state"]
                )));
            }
            let result = &v["result"];
            if let Some(p) = &csv {
                write_file(p, &c.export(&id, "points.csv")?)?;
            }
            if let Some(p) = &svg {
                write_file(p, &c.export(&id, "plot.svg")?)?;
            }
            if csv.is_none() && svg.is_none() {
                write_json(stdout, result)?;
            }
            Ok(())
        }
        other => Err(CliError::Failure(format!("{other:?} is not handled here"))),
    }
}

/// Tokens given on the command line (or comma-separated in the
/// environment) and one per line in `file`, trimmed, the empty ones left out.
fn secrets(
    given: Vec<String>,
    file: Option<&std::path::Path>,
    flag: &str,
) -> Result<Vec<String>, CliError> {
    let mut all = given;
    if let Some(f) = file {
        let text = std::fs::read_to_string(f)
            .map_err(|e| CliError::Input(format!("{flag} {} cannot be read: {e}", f.display())))?;
        all.extend(text.lines().map(str::to_owned));
    }
    let all: Vec<String> = all
        .into_iter()
        .map(|t| t.trim().to_string())
        .filter(|t| !t.is_empty())
        .collect();
    // A token is a password anyone on the lab's network may guess at:
    // refuse one short enough to guess (the ones `serve` makes are 48 hex
    // digits). Its length is named, never the token.
    if let Some(short) = all.iter().find(|t| t.chars().count() < MIN_TOKEN_CHARS) {
        return Err(CliError::Input(format!(
            "{flag}: a token of {} characters is too short: give at least {MIN_TOKEN_CHARS} (e.g. `openssl rand -hex 32`), or none and serve makes one",
            short.chars().count()
        )));
    }
    Ok(all)
}

/// The shortest token `serve` accepts (characters).
pub const MIN_TOKEN_CHARS: usize = 16;

/// A lease from 300 ms (tests) to 10 minutes.
fn check_lease_ms(lease_ms: i64) -> Result<(), CliError> {
    if (300..=600_000).contains(&lease_ms) {
        Ok(())
    } else {
        Err(CliError::Input(format!(
            "--lease-ms = {lease_ms}: a lease lasts 300 to 600000 ms"
        )))
    }
}

/// Logs to stderr. A log that cannot be written (its disk full) is
/// skipped, never reported on stderr: that report panics, dropping the
/// request.
fn init_logs() {
    use std::io::IsTerminal;
    let _ = tracing_subscriber::fmt()
        .log_internal_errors(false)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .try_init();
}

fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--token`/`ZWIDTH_TOKENS` and `--agent-token`/`ZWIDTH_AGENT_TOKENS`
    /// with their files: every non-empty token once trimmed, the flag's own
    /// values first; an unreadable file named with its flag.
    #[test]
    fn secrets_merge_the_flag_and_the_file_and_drop_blanks() {
        let dir = std::env::temp_dir().join(format!("zwidth-secrets-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("tokens");
        let (a, b, c) = ("a".repeat(16), "b".repeat(17), "c".repeat(40));
        std::fs::write(&f, format!("{b}\n\n  {c} \r\n")).unwrap();
        let got = secrets(
            vec![format!(" {a} "), String::new()],
            Some(&f),
            "--token-file",
        )
        .unwrap();
        assert_eq!(got, [a.clone(), b.clone(), c.clone()]);
        assert_eq!(
            secrets(vec![a.clone()], None, "--token-file").unwrap(),
            std::slice::from_ref(&a)
        );
        // Fifteen characters are refused (issue 45: tokens had no minimum),
        // naming the flag and the length, never the token.
        std::fs::write(&f, format!("{b}\n{}\n", "s".repeat(15))).unwrap();
        match secrets(vec![], Some(&f), "--token-file") {
            Err(CliError::Input(m)) => {
                assert!(
                    m.starts_with(
                        "--token-file: a token of 15 characters is too short: give at least 16"
                    ),
                    "{m}"
                );
                assert!(!m.contains(&"s".repeat(15)), "{m}");
            }
            other => panic!("{other:?}"),
        }
        let missing = dir.join("nope");
        match secrets(vec![], Some(&missing), "--agent-token-file") {
            Err(CliError::Input(m)) => {
                assert!(m.starts_with("--agent-token-file "), "{m}");
                assert!(m.contains("nope"), "{m}");
            }
            other => panic!("{other:?}"),
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
