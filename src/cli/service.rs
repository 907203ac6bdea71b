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
            request_timeout_s,
        } => {
            let mut tokens = tokens;
            if let Some(f) = &token_file {
                let text = std::fs::read_to_string(f).map_err(|e| {
                    CliError::Input(format!("--token-file {} cannot be read: {e}", f.display()))
                })?;
                tokens.extend(text.lines().map(str::to_owned));
            }
            let rigs: Vec<std::sync::Arc<dyn crate::rig::Rig>> =
                crate::rig::SimulatedRig::parse_list(&rigs)
                    .map_err(|e| CliError::Input(format!("--rigs: {e}")))?
                    .into_iter()
                    .map(|r| std::sync::Arc::new(r) as std::sync::Arc<dyn crate::rig::Rig>)
                    .collect();
            use std::io::IsTerminal;
            let _ = tracing_subscriber::fmt()
                .with_writer(std::io::stderr)
                .with_ansi(std::io::stderr().is_terminal())
                .with_env_filter(
                    tracing_subscriber::EnvFilter::try_from_default_env()
                        .unwrap_or_else(|_| "info".into()),
                )
                .try_init();
            let rt = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
            let tokens: Vec<String> = tokens
                .into_iter()
                .map(|t| t.trim().to_string())
                .filter(|t| !t.is_empty())
                .collect();
            rt.block_on(crate::http::serve(crate::http::ServeConfig {
                db,
                bind,
                tokens,
                allow_origins,
                rigs,
                request_timeout_s,
            }))
            .map_err(|e| {
                if e.starts_with("refusing") {
                    CliError::Input(e)
                } else {
                    CliError::Failure(e)
                }
            })
        }
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
            let v = client(server).submit(
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
        Command::Openapi => writeln!(stdout, "{}", crate::http::openapi_json()).map_err(io),
        Command::Backup { db, out } => {
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
        Command::Status { id, server } => write_json(stdout, &client(server).status(&id)?),
        Command::Watch { id, server } => {
            let v = client(server).watch(&id)?;
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
            let c = client(server);
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
