//! Beyond one machine (issue 14): API processes and `zwidth worker`
//! processes on one PostgreSQL database, started as a user starts them,
//! against the single-process SQLite service. Needs `ZWIDTH_TEST_PG` (see
//! tests/it/common/pg.rs); without it these tests are skipped, unless
//! `ZWIDTH_REQUIRE_PG=1` (CI), where they fail.

use std::process::Child;
use std::time::{Duration, Instant};

use crate::common::*;

const TOKEN: &str = "distributed-test-token";

/// The 2011 boundary trace of the seed device (time domain, ~540 trials,
/// ~1 s in a test build).
const TRACE: &str = r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
  "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability","search":"trace"}"#;

/// The same trace with a Kalman filter at reference accuracy (~1100
/// trials, ~2.5 s in a test build): long enough to kill or stop a worker
/// in the middle.
const SLOW: &str = r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
  "estimator":{"kind":"kalman","q":1e6}},"method":"time","criterion":"stability","search":"trace","accuracy":"reference"}"#;

/// Quick ones: an automatic-B bisection (columns dropped past its end), a
/// compare of two estimators, a grid.
const QUICK: [&str; 3] = [
    r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},
        "method":"analytic","b_max":5000,"k_max":1e6,"accuracy":{"preset":"draft","b_step":100}}"#,
    r#"{"kind":"compare","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},
        "estimators":[{"kind":"fdm"},{"kind":"butterworth","cutoff_hz":50}]}"#,
    r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},
        "method":"analytic","search":"grid","b":[0,20,40],"accuracy":{"k_step":2000},"k_max":20000}"#,
];

/// Column-heavy ones (issue 14's work units: one per B column): a
/// time-domain bisection over a B list, and one over an automatic B range
/// (queued in batches; the columns past its end dropped).
const COLUMNS: [&str; 3] = [
    r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
        "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability","b":[0,10,20,30,40,50]}"#,
    r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
        "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability",
        "b_max":400,"accuracy":{"preset":"draft","b_step":40}}"#,
    // A tune: a light driver whose evaluation maps' columns are units.
    r#"{"kind":"tune","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
        "estimator":{"kind":"butterworth","cutoff_hz":500}},"params":{"cutoff_hz":{"min":300,"max":600}},
        "objective":"k_width","method":"time","criterion":"stability","max_evaluations":4,"finalists":0,"b":[0,20,40]}"#,
];

fn units(base: &str, id: &str) -> Vec<serde_json::Value> {
    get(&format!("{base}/v1/experiments/{id}/units"))
        .as_array()
        .unwrap()
        .clone()
}

struct Procs {
    children: Vec<Child>,
    dir: std::path::PathBuf,
}

impl Drop for Procs {
    fn drop(&mut self) {
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
        // ZWIDTH_KEEP=1 keeps the processes' logs for a failure's reading.
        if std::env::var_os("ZWIDTH_KEEP").is_none() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

fn fresh_dir(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("zwidth-dist-{tag}-{}", uuid_like()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An API process on `db` (no experiments of its own with `api_only`):
/// its base URL.
fn api(p: &mut Procs, db: &str, api_only: bool, log: &str) -> String {
    let mut args = vec![
        "serve",
        "--db",
        db,
        "--bind",
        "127.0.0.1:0",
        "--token",
        TOKEN,
        "--rigs",
        "sim:1",
    ];
    if api_only {
        args.push("--api-only");
    }
    let (child, line) = spawn_ready(&args, &p.dir, log);
    p.children.push(child);
    let base = line.rsplit(' ').next().unwrap().to_string();
    assert!(base.starts_with("http://127.0.0.1:"), "{line}");
    register_token(&base, TOKEN);
    base
}

/// A worker on `db` with one single-thread simulator: its id.
fn worker(p: &mut Procs, db: &str, lease_ms: &str, log: &str) -> String {
    let (child, line) = spawn_ready(
        &[
            "worker",
            "--db",
            db,
            "--rigs",
            "sim:1",
            "--lease-ms",
            lease_ms,
        ],
        &p.dir,
        log,
    );
    p.children.push(child);
    // "zwidth worker ID running rigs sim:1 from postgres://…" (no password)
    assert!(
        line.contains(" running rigs sim:1 from postgres://"),
        "{line}"
    );
    assert!(!line.contains(":zwidth-ci-"), "the password shows: {line}");
    line.split(' ').nth(2).unwrap().to_string()
}

fn submit(base: &str, spec: &str) -> String {
    let (code, v, _) = post(&format!("{base}/v1/experiments"), &spec.replace('\n', ""));
    assert_eq!(code, 202, "{v}");
    v["id"].as_str().unwrap().to_string()
}

fn trials(base: &str, id: &str) -> serde_json::Value {
    get(&format!("{base}/v1/experiments/{id}/trials?limit=10000"))
}

/// What must be equal between two runs of one spec: the result without
/// its wall time, and every stored trial in order.
fn outcome(
    base: &str,
    id: &str,
    done: &serde_json::Value,
) -> (serde_json::Value, serde_json::Value) {
    assert_eq!(done["state"], "succeeded", "{done}");
    let mut r = done["result"].clone();
    strip_times(&mut r);
    (r, trials(base, id))
}

fn strip_times(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(m) => {
            // Wall times: elapsed_s, search_s, mean_search_evaluation_s, …
            m.retain(|k, _| !k.ends_with("_s"));
            m.values_mut().for_each(strip_times);
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(strip_times),
        _ => {}
    }
}

/// The same campaign on one process with SQLite and on one API process
/// and three workers with PostgreSQL: every result and every stored trial
/// equal, the boundaries byte-equal, and the work spread over the workers.
#[test]
fn a_campaign_on_three_workers_equals_one_process() {
    let Some(url) = pg::fresh_database_blocking("campaign") else {
        return;
    };
    let specs: Vec<&str> = std::iter::once(TRACE).chain(QUICK).chain(COLUMNS).collect();
    // One process, SQLite.
    let mut one = Procs {
        children: vec![],
        dir: fresh_dir("one"),
    };
    let db = one.dir.join("one.db").display().to_string();
    let base = api(&mut one, &db, false, "serve.err");
    let ids: Vec<String> = specs.iter().map(|s| submit(&base, s)).collect();
    let want: Vec<_> = ids
        .iter()
        .map(|id| outcome(&base, id, &wait_end(&base, id, 120)))
        .collect();
    // One process computes its maps itself: no units.
    assert!(ids.iter().all(|id| units(&base, id).is_empty()));
    drop(one);
    // One API process and three workers, PostgreSQL.
    let mut many = Procs {
        children: vec![],
        dir: fresh_dir("many"),
    };
    let base = api(&mut many, &url, true, "api.err");
    let workers: Vec<String> = (0..3)
        .map(|i| worker(&mut many, &url, "15000", &format!("w{i}.err")))
        .collect();
    let ids: Vec<String> = specs.iter().map(|s| submit(&base, s)).collect();
    let mut ran_on = std::collections::BTreeSet::new();
    for (i, id) in ids.iter().enumerate() {
        let done = wait_end(&base, id, 120);
        let got = outcome(&base, id, &done);
        assert_eq!(got.0, want[i].0, "result of {}", specs[i]);
        assert_eq!(
            serde_json::to_string(&got.0["boundary"]).unwrap(),
            serde_json::to_string(&want[i].0["boundary"]).unwrap()
        );
        assert_eq!(got.1, want[i].1, "stored trials of {}", specs[i]);
        assert_eq!(done["attempt"], 1, "{done}");
        let w = done["worker"].as_str().unwrap().to_string();
        assert!(workers.contains(&w), "{w} not in {workers:?}");
        ran_on.insert(w);
    }
    assert!(ran_on.len() >= 2, "one worker ran everything: {ran_on:?}");
    // Every map went out as units: a trace or an analytic map whole
    // (column -1), a bisection one unit per B column; each done once, on
    // the first attempt; the columns spread over the workers.
    let mut column_workers = std::collections::BTreeSet::new();
    for (i, id) in ids.iter().enumerate() {
        let us = units(&base, id);
        assert!(!us.is_empty(), "no units for {}", specs[i]);
        for u in &us {
            assert_eq!(
                (u["state"].as_str(), u["attempt"].as_i64()),
                (Some("done"), Some(1)),
                "{u}"
            );
            assert!(workers.iter().any(|w| u["worker"] == w.as_str()), "{u}");
        }
        if COLUMNS.contains(&specs[i]) {
            if specs[i].contains("\"tune\"") {
                // 4 evaluation maps (scopes 0…3) of 3 columns each.
                let places: Vec<(i64, i64)> = us
                    .iter()
                    .map(|u| (u["scope"].as_i64().unwrap(), u["column"].as_i64().unwrap()))
                    .collect();
                let want: Vec<(i64, i64)> =
                    (0..4).flat_map(|s| (0..3).map(move |c| (s, c))).collect();
                assert_eq!(places, want);
            } else {
                let cols: Vec<i64> = us.iter().map(|u| u["column"].as_i64().unwrap()).collect();
                assert_eq!(
                    cols,
                    (0..us.len() as i64).collect::<Vec<_>>(),
                    "one unit per column"
                );
                assert!(cols.len() >= 6, "{cols:?}");
            }
            column_workers.extend(us.iter().map(|u| u["worker"].as_str().unwrap().to_string()));
        } else {
            assert!(us.iter().all(|u| u["column"] == -1), "{us:?}");
        }
    }
    assert!(
        column_workers.len() >= 2,
        "one worker ran every column: {column_workers:?}"
    );
    // /metrics counts the workers (each reports itself every second).
    wait_for("three idle workers in /metrics", 10, || {
        let m = ureq::get(&format!("{base}/metrics"))
            .call()
            .unwrap()
            .into_string()
            .unwrap();
        m.contains("zwidth_workers{busy=\"false\"} 3")
    });
}

/// Wait until `id` has at least `n` trials stored.
fn wait_trials(base: &str, id: &str, n: usize) {
    wait_for(&format!("{n} trials stored"), 60, || {
        trials(base, id).as_array().unwrap().len() >= n
    });
}

/// SLOW's result from the library in this process.
fn slow_by_the_library() -> zwidth::zwidth::search::MapResult {
    let spec: zwidth::experiment::ExperimentSpec = serde_json::from_str(SLOW).unwrap();
    let zwidth::experiment::ExperimentSpec::Map(m) = spec else {
        unreachable!()
    };
    zwidth::zwidth::search::map(&m).unwrap()
}

fn assert_is_slow_s_result(done: &serde_json::Value, stored: &serde_json::Value) {
    let want = slow_by_the_library();
    let got = &done["result"];
    assert_eq!(got["trials"].as_u64().unwrap() as usize, want.trials);
    assert_eq!(got["k_width"].as_f64().unwrap(), want.k_width);
    assert_eq!(got["b_width"].as_f64().unwrap(), want.b_width);
    assert_eq!(
        got["boundary"],
        serde_json::to_value(&want.boundary).unwrap(),
        "the boundary"
    );
    // Every trial stored once: as many as the result has, all distinct.
    let stored = stored.as_array().unwrap();
    assert_eq!(stored.len(), want.trials, "one stored trial per trial");
    let keys: std::collections::BTreeSet<(u64, u64)> = stored
        .iter()
        .map(|t| {
            (
                t["point"]["k"].as_f64().unwrap().to_bits(),
                t["point"]["b"].as_f64().unwrap().to_bits(),
            )
        })
        .collect();
    assert_eq!(keys.len(), want.trials);
}

/// SIGKILL a worker while its run has stored trials: another worker claims
/// it when the lease ends (attempt 2), replays what is stored, and the
/// result is the library's; no trial is stored twice.
#[test]
fn a_killed_worker_s_run_is_claimed_again_with_the_same_result() {
    let Some(url) = pg::fresh_database_blocking("killed") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("killed"),
    };
    let base = api(&mut p, &url, true, "api.err");
    let first = worker(&mut p, &url, "1000", "w1.err");
    let id = submit(&base, SLOW);
    wait_trials(&base, &id, 60);
    let v = get(&format!("{base}/v1/experiments/{id}"));
    assert_eq!(
        (v["worker"].as_str(), v["attempt"].as_i64()),
        (Some(first.as_str()), Some(1))
    );
    p.children[1].kill().unwrap(); // SIGKILL
    p.children[1].wait().unwrap();
    let second = worker(&mut p, &url, "1000", "w2.err");
    let done = wait_end(&base, &id, 120);
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(done["attempt"], 2, "{done}");
    assert_eq!(done["worker"], second.as_str());
    assert_is_slow_s_result(&done, &trials(&base, &id));
    // Its one unit (the whole trace) was claimed again too, and finished
    // by the second worker.
    let us = units(&base, &id);
    assert_eq!(us.len(), 1, "{us:?}");
    assert_eq!(
        (
            us[0]["state"].as_str(),
            us[0]["attempt"].as_i64(),
            us[0]["worker"].as_str()
        ),
        (Some("done"), Some(2), Some(second.as_str()))
    );
    let log = std::fs::read_to_string(p.dir.join("w2.err")).unwrap();
    assert!(log.contains("stored_trials="), "{log}");
}

/// CPU time (user and system, s) process `pid` has used, from
/// /proc/PID/stat (fields 14 and 15, clock ticks: proc(5)).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    // After the command's closing parenthesis come fields 3, 4, …
    let fields: Vec<&str> = stat[stat.rfind(')').unwrap() + 2..]
        .split_whitespace()
        .collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    // SAFETY: sysconf reads a constant of the system.
    ticks / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64
}

/// SIGSTOP a worker past its lease, then SIGCONT: another worker has
/// claimed the run; the stopped one's heartbeat and writes change nothing,
/// it abandons the run, and the result is the library's.
#[test]
fn a_stopped_worker_past_its_lease_changes_nothing_and_abandons_the_run() {
    let Some(url) = pg::fresh_database_blocking("stopped") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("stopped"),
    };
    let base = api(&mut p, &url, true, "api.err");
    let first = worker(&mut p, &url, "1000", "w1.err");
    let id = submit(&base, SLOW);
    wait_trials(&base, &id, 30);
    let pid = p.children[1].id().to_string();
    let signal = |s: &str| {
        assert!(std::process::Command::new("kill")
            .args([s, &pid])
            .status()
            .unwrap()
            .success())
    };
    signal("-STOP");
    let second = worker(&mut p, &url, "1000", "w2.err");
    // The run (its driver) and its unit (the whole trace): both claimed
    // by the second worker before the first wakes up; /v1/rigs shows the
    // unit computing there.
    let on_second =
        |u: &serde_json::Value| u["experiment_id"] == id.as_str() && u["worker"] == second.as_str();
    wait_for(
        "the run and its unit claimed by the second worker",
        30,
        || {
            let rigs = get(&format!("{base}/v1/rigs"));
            get(&format!("{base}/v1/experiments/{id}"))["worker"] == second.as_str()
                && rigs[0]["units"].as_array().unwrap().iter().any(on_second)
        },
    );
    signal("-CONT");
    // The lost-lease path stops the stale run within a stated bound: 5 s
    // after SIGCONT (its first 100 ms tick finds the lease taken; the
    // trial in flight ends; the registry hears it within a second) the
    // first worker has abandoned the run and its unit and runs nothing.
    let resumed = Instant::now();
    // It stops computing, not only reporting (issue 45 item 14): from
    // 0.5 s to 1.5 s after SIGCONT it uses under 0.3 s of CPU. Three
    // cancels serve the lost lease, each enough alone (the flush that finds
    // the lease taken, the heartbeat's `Lost`, the self-stop when unheard
    // for a lease); without all three the stale trace goes on for the ~2 s
    // it has left (0.97 s of CPU in that second, measured), and the
    // registry reports it idle only after that.
    let stopped_pid: u32 = pid.parse().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let before = cpu_seconds(stopped_pid);
    std::thread::sleep(Duration::from_millis(1000));
    let used = cpu_seconds(stopped_pid) - before;
    assert!(
        used < 0.3,
        "the stale run still computes: {used:.2} s of CPU in 1 s"
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    let store = rt
        .block_on(zwidth::store::Store::connect(
            &zwidth::store::Location::Postgres(url.clone()),
        ))
        .unwrap();
    let first_runs = || {
        rt.block_on(store.workers(60_000))
            .unwrap()
            .into_iter()
            .find(|w| w.id == first)
            .map(|w| w.running)
    };
    wait_for(
        "the stopped worker to abandon the run within 5 s",
        5,
        || {
            std::fs::read_to_string(p.dir.join("w1.err"))
                .unwrap()
                .contains("lease was taken over: abandoning")
                && first_runs() == Some(None)
        },
    );
    assert!(resumed.elapsed() < Duration::from_secs(5));
    eprintln!("abandoned and idle {:?} after SIGCONT", resumed.elapsed());
    let done = wait_end(&base, &id, 120);
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(
        (done["attempt"].as_i64(), done["worker"].as_str()),
        (Some(2), Some(second.as_str()))
    );
    assert_is_slow_s_result(&done, &trials(&base, &id));
    let us = units(&base, &id);
    assert_eq!(
        (
            us[0]["state"].as_str(),
            us[0]["attempt"].as_i64(),
            us[0]["worker"].as_str()
        ),
        (Some("done"), Some(2), Some(second.as_str()))
    );
    // And it goes on serving: alive, idle.
    assert!(p.children[1].try_wait().unwrap().is_none());
}

/// Kill the API process mid-campaign: the workers go on; an API process
/// started again serves the same state, the runs finished meanwhile.
#[test]
fn killing_the_api_leaves_the_workers_going() {
    let Some(url) = pg::fresh_database_blocking("api") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("api"),
    };
    let base = api(&mut p, &url, true, "api1.err");
    let _w = worker(&mut p, &url, "15000", "w1.err");
    let ids: Vec<String> = [SLOW, QUICK[0], QUICK[1]]
        .iter()
        .map(|s| submit(&base, s))
        .collect();
    wait_trials(&base, &ids[0], 30);
    p.children[0].kill().unwrap();
    p.children[0].wait().unwrap();
    let killed = Instant::now();
    // Meanwhile, straight from the database: the worker finishes them.
    let rt = tokio::runtime::Runtime::new().unwrap();
    let store = rt
        .block_on(zwidth::store::Store::connect(
            &zwidth::store::Location::Postgres(url.clone()),
        ))
        .unwrap();
    wait_for("every run finished without an API process", 120, || {
        ids.iter().all(|id| {
            rt.block_on(store.get(id)).unwrap().unwrap().state
                == zwidth::store::ExperimentState::Succeeded
        })
    });
    assert!(killed.elapsed() < Duration::from_secs(120));
    let base2 = api(&mut p, &url, true, "api2.err");
    for id in &ids {
        let v = get(&format!("{base2}/v1/experiments/{id}"));
        assert_eq!(v["state"], "succeeded", "{v}");
        assert_eq!(v["attempt"], 1, "never taken over: {v}");
    }
    let done = get(&format!("{base2}/v1/experiments/{}", ids[0]));
    assert_is_slow_s_result(&done, &trials(&base2, &ids[0]));
}

/// The 2018 device at reference accuracy over six B values: six column
/// units of ~0.6 s (frequency engine, BLA verdicts with intervals).
const SEED_COLUMNS: &str = r#"{"kind":"map","scene":{"device":{"mass":0.52,"damping":13.2,"coulomb":0.19,"quantization":1e-6},
  "loop":{"sample_hz":1000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":499,"order":2}},
  "accuracy":"reference","b":[0,25,50,75,100,125]}"#;

/// SEED_COLUMNS over 240 B values: 240 column units of ~0.6 s, ≥ 60 s on
/// two workers.
fn long_columns() -> String {
    let bs: Vec<String> = (0..240).map(|i| (2.5 * i as f64).to_string()).collect();
    SEED_COLUMNS.replace(
        r#""b":[0,25,50,75,100,125]"#,
        &format!(r#""b":[{}]"#, bs.join(",")),
    )
}

/// SIGTERM (`docker stop`) the worker driving a run while units are out:
/// it stops within a trial, its run interrupted and its unit queued again;
/// the other worker takes the run over (attempt 2), its units go on, and
/// the result is the library's.
#[test]
fn a_driver_stopped_gracefully_hands_its_run_and_units_over() {
    let Some(url) = pg::fresh_database_blocking("graceful") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("graceful"),
    };
    let base = api(&mut p, &url, true, "api.err");
    let ids = [
        worker(&mut p, &url, "15000", "w1.err"),
        worker(&mut p, &url, "15000", "w2.err"),
    ];
    let id = submit(&base, SEED_COLUMNS);
    wait_for("two units done", 60, || {
        units(&base, &id)
            .iter()
            .filter(|u| u["state"] == "done")
            .count()
            >= 2
    });
    let v = get(&format!("{base}/v1/experiments/{id}"));
    let driver = ids.iter().position(|w| v["worker"] == w.as_str()).unwrap();
    let pid = p.children[1 + driver].id().to_string();
    assert!(std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap()
        .success());
    let status = p.children[1 + driver].wait().unwrap();
    assert!(status.success(), "a clean stop: {status}");
    let done = wait_end(&base, &id, 120);
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(done["attempt"], 2, "{done}");
    assert_eq!(done["worker"], ids[1 - driver].as_str());
    let us = units(&base, &id);
    assert_eq!(us.len(), 6);
    assert!(us.iter().all(|u| u["state"] == "done"), "{us:?}");
    // The library's map, in this process.
    let spec: zwidth::experiment::ExperimentSpec =
        serde_json::from_str(&SEED_COLUMNS.replace('\n', "")).unwrap();
    let zwidth::experiment::ExperimentSpec::Map(m) = spec else {
        unreachable!()
    };
    let want = zwidth::zwidth::search::map(&m).unwrap();
    assert_eq!(
        done["result"]["boundary"],
        serde_json::to_value(&want.boundary).unwrap()
    );
    assert_eq!(
        trials(&base, &id).as_array().unwrap().len(),
        want.trials,
        "every trial stored once"
    );
}

/// Cancel through another API process than the one it was submitted to
/// (a write to the database, not a message to a process) while two workers
/// compute the run's units: the driver (a worker) and every unit stop
/// within a few heartbeats (1 s each; asserted: 10 s), nothing is claimed
/// again, /v1/rigs shows no unit computing and /metrics no busy worker.
#[test]
fn a_cancel_reaches_units_on_other_workers() {
    let Some(url) = pg::fresh_database_blocking("cancel") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("cancel"),
    };
    let base = api(&mut p, &url, true, "api.err");
    let other = api(&mut p, &url, true, "api2.err");
    for i in 0..2 {
        worker(&mut p, &url, "15000", &format!("w{i}.err"));
    }
    // A map that would take ≥ 60 s uncancelled (issue 45 item 14): so only
    // a cancel that reaches the driver stops it within the bound (SEED_COLUMNS
    // ends by itself in a few seconds, cancelled or not).
    let id = submit(&base, &long_columns());
    wait_for("units computing on both workers", 60, || {
        let rigs = get(&format!("{base}/v1/rigs"));
        rigs[0]["units"].as_array().unwrap().len() >= 2
    });
    let (code, v, _) = post(&format!("{other}/v1/experiments/{id}/cancel"), "");
    assert_eq!(code, 200, "{v}");
    let cancelled = Instant::now();
    // The driver stops: no worker reports running an experiment.
    wait_for("no busy worker", 10, || {
        let m = ureq::get(&format!("{base}/metrics"))
            .call()
            .unwrap()
            .into_string()
            .unwrap();
        m.contains("zwidth_workers{busy=\"true\"} 0")
    });
    wait_for("no unit computing", 10, || {
        get(&format!("{base}/v1/rigs"))[0]["units"]
            .as_array()
            .unwrap()
            .is_empty()
            && units(&base, &id)
                .iter()
                .all(|u| u["state"] != "running" && u["state"] != "queued")
    });
    assert!(cancelled.elapsed() < Duration::from_secs(10));
    let v = get(&format!("{base}/v1/experiments/{id}"));
    assert_eq!(v["state"], "cancelled", "{v}");
    // And it stays so: no unit of it is claimed again.
    std::thread::sleep(Duration::from_secs(2));
    let us = units(&base, &id);
    assert!(
        us.iter()
            .all(|u| u["state"] == "cancelled" || u["state"] == "done"),
        "{us:?}"
    );
    assert!(us.iter().any(|u| u["state"] == "cancelled"), "{us:?}");
}

/// Issue 45 item 14: a cancel written by another API process reaches the
/// driver through its heartbeat (`Held::Cancelled`), not only its units.
/// One worker, one runner: the run would take ≥ 60 s uncancelled, and the
/// next submission can start only once the driver has let the cancelled
/// run go, so a driver that ignored the cancel (waiting for units that
/// never finish) would hold it past the bound. (`no busy worker` in the
/// test above reads the database's state, which a cancel changes at once:
/// it passed with the heartbeat's cancel removed.)
#[test]
fn a_cancel_from_another_process_frees_the_driver_for_the_next_run() {
    let Some(url) = pg::fresh_database_blocking("cancel_driver") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("cancel_driver"),
    };
    let base = api(&mut p, &url, true, "api.err");
    let other = api(&mut p, &url, true, "api2.err");
    worker(&mut p, &url, "15000", "w.err");
    let id = submit(&base, &long_columns());
    // Past the planning of its units (a cancel then would reach the driver
    // as a lost lease when it plans them): one unit done.
    wait_for("a unit done", 60, || {
        units(&base, &id).iter().any(|u| u["state"] == "done")
    });
    let (code, v, _) = post(&format!("{other}/v1/experiments/{id}/cancel"), "");
    assert_eq!(code, 200, "{v}");
    let next = submit(&base, QUICK[0]);
    // The lease is 15 s, heartbeats every quarter of it: the driver hears
    // the cancel within ~4 s, then its runner takes the next run.
    wait_for("the next run done on the same worker", 20, || {
        get(&format!("{base}/v1/experiments/{next}"))["state"] == "succeeded"
    });
    let v = get(&format!("{base}/v1/experiments/{id}"));
    assert_eq!(v["state"], "cancelled", "{v}");
}

/// Issue 30, defect 7: a run on a rig that no live worker runs says so
/// (`waiting_for_rig`, in the API and on its page) instead of waiting
/// silently; an API process started again says it too (it is read from
/// the workers' table); a worker for that rig then runs it.
#[test]
fn a_run_on_a_rig_no_worker_runs_says_why_it_waits() {
    let Some(url) = pg::fresh_database_blocking("lonely") else {
        return;
    };
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("lonely"),
    };
    let api_args = [
        "serve",
        "--db",
        &url,
        "--bind",
        "127.0.0.1:0",
        "--token",
        TOKEN,
        "--rigs",
        "sim:1,lonely:1",
        "--api-only",
    ];
    let (child, line) = spawn_ready(&api_args, &p.dir, "api.err");
    p.children.push(child);
    let base = line.rsplit(' ').next().unwrap().to_string();
    register_token(&base, TOKEN);
    worker(&mut p, &url, "15000", "w0.err");
    let small = QUICK[0];
    let (code, v, _) = post(
        &format!("{base}/v1/experiments?rig=lonely"),
        &small.replace('\n', ""),
    );
    assert_eq!(code, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    let waiting = |base: &str| {
        let v = get(&format!("{base}/v1/experiments/{id}"));
        assert_eq!(v["state"], "queued", "{v}");
        v["progress"]["waiting_for_rig"].as_str().map(str::to_owned)
    };
    // (The worker's first report may come after the API's first read.)
    let mut why = None;
    wait_for("waiting_for_rig naming the live worker's rig", 20, || {
        why = waiting(&base);
        why.as_deref().is_some_and(|w| w.contains("sim"))
    });
    let why = why.unwrap();
    assert!(
        why.contains("no live worker runs rig lonely") && why.contains("sim"),
        "{why}"
    );
    let page = ureq::get(&format!("{base}/runs/{id}"))
        .call()
        .unwrap()
        .into_string()
        .unwrap();
    assert!(
        page.contains("waiting for the rig") && page.contains("no live worker runs rig lonely"),
        "{page}"
    );
    // The API process killed and started again: it says so again.
    let mut old = p.children.remove(0);
    let _ = old.kill();
    let _ = old.wait();
    let (child, line) = spawn_ready(&api_args, &p.dir, "api2.err");
    p.children.push(child);
    let base = line.rsplit(' ').next().unwrap().to_string();
    register_token(&base, TOKEN);
    wait_for("waiting_for_rig after a restart", 20, || {
        waiting(&base).is_some_and(|w| w.contains("lonely"))
    });
    // A worker for the rig runs it.
    let (child, _) = spawn_ready(
        &["worker", "--db", &url, "--rigs", "lonely:1"],
        &p.dir,
        "w1.err",
    );
    p.children.push(child);
    assert_eq!(wait_end(&base, &id, 120)["state"], "succeeded");
}

/// A TCP proxy to `target` that forwards both ways until `frozen` is set,
/// then forwards nothing and closes nothing: a network cut off (no reset),
/// as a pulled cable or a dropped VPN leaves a connection.
struct Freezer {
    port: u16,
    frozen: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

fn freezer(target: std::net::SocketAddr) -> Freezer {
    use std::io::{Read, Write};
    use std::sync::atomic::{AtomicBool, Ordering};
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let frozen = std::sync::Arc::new(AtomicBool::new(false));
    let f = frozen.clone();
    std::thread::spawn(move || {
        for client in l.incoming().flatten() {
            let Ok(server) = std::net::TcpStream::connect(target) else {
                continue;
            };
            for (mut from, mut to) in [
                (client.try_clone().unwrap(), server.try_clone().unwrap()),
                (server, client),
            ] {
                let f = f.clone();
                std::thread::spawn(move || {
                    let mut buf = [0u8; 16 * 1024];
                    while let Ok(n) = from.read(&mut buf) {
                        while f.load(Ordering::Relaxed) {
                            std::thread::sleep(Duration::from_millis(50));
                        }
                        if n == 0 || to.write_all(&buf[..n]).is_err() {
                            break;
                        }
                    }
                });
            }
        }
    });
    Freezer { port, frozen }
}

/// Issue 45 item 8: a worker whose database connection is cut off mid-run
/// (the proxy stops forwarding; nothing is reset) hung: its store calls
/// were awaited without a bound, so the "no heartbeat for a whole lease"
/// check never ran (measured once: 85 s, unbounded in principle). Now every
/// store call of the supervision loop is bounded: the worker abandons the
/// run and its units within 1.5 leases of the cut (3 s lease: ≤ 4.5 s;
/// asserted ≤ 8 s).
#[test]
fn a_worker_cut_off_from_its_database_abandons_the_run_within_its_lease() {
    let Some(url) = pg::fresh_database_blocking("cut") else {
        return;
    };
    let tls = pg::tls_url().expect("the TCP listener of .ci/postgres (ZWIDTH_TEST_PG_TLS)");
    let db = url.split('?').next().unwrap().rsplit('/').next().unwrap();
    let tcp = pg::with_database(&tls, db);
    // localhost:PORT of the server, and the same through the proxy.
    let port: u16 = tcp
        .split("@localhost:")
        .nth(1)
        .unwrap()
        .split('/')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let proxy = freezer(std::net::SocketAddr::from(([127, 0, 0, 1], port)));
    let through = tcp.replace(
        &format!("@localhost:{port}/"),
        &format!("@localhost:{}/", proxy.port),
    );
    let mut p = Procs {
        children: vec![],
        dir: fresh_dir("cut"),
    };
    let base = api(&mut p, &url, true, "api.err");
    worker(&mut p, &through, "3000", "w.err");
    let id = submit(&base, &long_columns());
    wait_for("units computing on the worker", 60, || {
        !get(&format!("{base}/v1/rigs"))[0]["units"]
            .as_array()
            .unwrap()
            .is_empty()
    });
    proxy
        .frozen
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let cut = Instant::now();
    let log = || std::fs::read_to_string(p.dir.join("w.err")).unwrap_or_default();
    wait_for("the cut-off worker to abandon its run", 8, || {
        log().contains("no heartbeat went through for a whole lease: abandoning")
    });
    eprintln!(
        "abandoned {:.1} s after the cut",
        cut.elapsed().as_secs_f64()
    );
    // The run is not lost: its lease runs out and it waits to be claimed
    // again (no other worker here), nothing ended.
    let v = get(&format!("{base}/v1/experiments/{id}"));
    assert!(
        ["running", "queued", "interrupted"].contains(&v["state"].as_str().unwrap()),
        "{v}"
    );
}
