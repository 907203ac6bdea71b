//! The service as users run it: the real binary on 127.0.0.1:0 with a fresh
//! database, driven over HTTP.

use std::process::Command;
use std::time::{Duration, Instant};

use crate::common::*;

#[test]
fn submit_progress_result() {
    let s = start();
    let health = get(&format!("{}/healthz", s.base));
    assert_eq!(health["status"], "ok", "{health}");
    // Checked at start: a unix time in ms within the last minute.
    let now_ms = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as i64;
    let checked = health["database"]["checked_ms"].as_i64().unwrap();
    assert!((now_ms - 60_000..=now_ms).contains(&checked), "{health}");
    // An analytic strict-passivity map: b > KT/2 + |B| gives 16 400 N/m at B = 5.
    let body = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},
                  "criterion":"strict_passivity","b":[0,5]}"#;
    let (code, v, _) = post(&format!("{}/v1/experiments", s.base), body);
    assert_eq!(code, 202, "{v}");
    assert_eq!(v["state"], "queued");
    let id = v["id"].as_str().unwrap().to_string();
    let deadline = Instant::now() + Duration::from_secs(30);
    let done = loop {
        let v = get(&format!("{}/v1/experiments/{id}", s.base));
        if v["state"] == "succeeded" || v["state"] == "failed" {
            break v;
        }
        assert!(Instant::now() < deadline, "still {v}");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(done["state"], "succeeded", "{done}");
    let k5 = done["result"]["boundary"][1]["k_max"].as_f64().unwrap();
    assert!((k5 - 16_400.0).abs() < 1e-6, "{k5}");
    assert!(done["progress"]["trials_done"].as_i64().unwrap() >= 1);
    // The list is a page of summaries: no result unless asked for.
    let all = get(&format!("{}/v1/experiments", s.base));
    assert_eq!(all["experiments"].as_array().unwrap().len(), 1, "{all}");
    assert!(all["experiments"][0].get("result").is_none(), "{all}");
    let full = get(&format!("{}/v1/experiments?include=result", s.base));
    assert_eq!(
        full["experiments"][0]["result"]["boundary"][1]["k_max"],
        done["result"]["boundary"][1]["k_max"]
    );
}

#[test]
fn bad_inputs_are_problems_naming_the_field() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    for (body, needle) in [
        (
            r#"{"kind":"map","scene":{"device":{"mass":-1}}}"#,
            "scene.device.mass",
        ),
        (r#"{"kind":"map","scene":{},"method":"analytic"}"#, "method"),
        (
            r#"{"kind":"map","scene":{"estimator":{"kind":"butterworth","cutoff_hz":99999}}}"#,
            "scene.estimator.cutoff_hz",
        ),
        (r#"{"kind":"nope"}"#, r#""field":"kind""#),
        (
            r#"{"kind":"compare","estimators":[{"kind":"fdm"},{"kind":"butterworth","cutoff_hz":99999}]}"#,
            "estimators[1].cutoff_hz",
        ),
        (r#"{"kind":"compare","estimators":[]}"#, "estimators"),
        (
            r#"{"kind":"compare","resolve_rounds":4}"#,
            "resolve_rounds = 4 is not allowed: must be 0 to 3",
        ),
        (
            r#"{"kind":"compare","resolve_rounds":-1}"#,
            "not a valid experiment",
        ),
        (r#"not json"#, "not a valid experiment"),
        (
            r#"{"kind":"compare","accuracy":"fast"}"#,
            "not a valid experiment",
        ),
    ] {
        let (code, v, ct) = post(&url, body);
        assert_eq!(code, 422, "{body}: {v}");
        assert_eq!(ct, "application/problem+json");
        let text = v.to_string();
        assert!(text.contains(needle), "{body}: {text} lacks {needle}");
        assert_eq!(v["status"], 422);
    }
    // Nothing was stored by the bad requests.
    assert_eq!(get(&url)["experiments"].as_array().unwrap().len(), 0);
    let r = ureq::get(&format!("{}/v1/experiments/nope", s.base)).call();
    assert!(matches!(r, Err(ureq::Error::Status(404, _))));
}

#[test]
fn idempotency_key_and_cancel() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    // A long time-domain map, so it is still running when cancelled.
    let body = r#"{"kind":"map","scene":{"loop":{"sample_hz":10000,"render_hz":1000}},"method":"time","criterion":"stability","search":"trace","accuracy":"reference"}"#;
    let send = || {
        authed::post(&url)
            .set("idempotency-key", "abc-1")
            .set("content-type", "application/json")
            .send_string(body)
            .unwrap()
    };
    let first = send();
    assert_eq!(first.status(), 202);
    let v1: serde_json::Value = first.into_json().unwrap();
    let second = send();
    assert_eq!(second.status(), 200);
    let v2: serde_json::Value = second.into_json().unwrap();
    assert_eq!(v1["id"], v2["id"]);
    let id = v1["id"].as_str().unwrap();
    // Wait for it to run, cancel, and see it stop.
    let deadline = Instant::now() + Duration::from_secs(20);
    while get(&format!("{url}/{id}"))["state"] != "running" {
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(20));
    }
    // Some trials stored first, so that "stops storing" means something.
    let stored = |id: &str| {
        get(&format!("{url}/{id}/trials?limit=10000"))
            .as_array()
            .unwrap()
            .len()
    };
    wait_for("trials stored before the cancel", 30, || stored(id) >= 5);
    let (code, v, _) = post(&format!("{url}/{id}/cancel"), "");
    assert_eq!(code, 200, "{v}");
    assert_eq!(v["state"], "cancelled", "{v}");
    // The simulation stops: within a second no more trials reach the store
    // (the runner stores finished trials every 100 ms, so a second with the
    // same count, twice over, is ten store rounds without a new trial).
    let settled = |id: &str| {
        let before = stored(id);
        std::thread::sleep(Duration::from_millis(1000));
        before == stored(id)
    };
    wait_for("the stored trial count to stop growing", 3, || settled(id));
    assert!(settled(id), "trials still being stored after the cancel");
    // The state stays cancelled (it never flips to succeeded when the map
    // would have ended) and a second cancel is refused.
    assert_eq!(get(&format!("{url}/{id}"))["state"], "cancelled");
    let (code, _, _) = post(&format!("{url}/{id}/cancel"), "");
    assert_eq!(code, 409);
    // The rig is free: the next experiment on it (one at a time per rig)
    // starts and finishes, long before the cancelled reference-accuracy
    // trace could have ended (minutes).
    the_rig_runs_the_next_and_the_cancelled_stays(&s.base, id, 10);
}

#[test]
fn killed_mid_run_resumes_from_stored_trials_with_the_same_result() {
    // The 2011 boundary trace of the seed device (time domain, ~540 trials).
    let spec = r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
                   "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability","search":"trace"}"#;
    let s = start();
    let dir = s._dir.clone();
    let url = format!("{}/v1/experiments", s.base);
    let (code, v, _) = post(&url, spec);
    assert_eq!(code, 202);
    let id = v["id"].as_str().unwrap().to_string();
    // Let it get well into the run, then SIGKILL the server.
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let v = get(&format!("{url}/{id}"));
        assert!(
            v["state"] == "running" || v["state"] == "queued",
            "finished before it could be killed: {v}"
        );
        if v["state"] == "running" && v["progress"]["trials_done"].as_i64().unwrap() >= 60 {
            break;
        }
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(10));
    }
    // Trials are in the store before the kill (the runner stores them every
    // 100 ms): these are what the restart must replay.
    wait_for("60 trials stored", 30, || {
        get(&format!("{url}/{id}/trials?limit=10000"))
            .as_array()
            .unwrap()
            .len()
            >= 60
    });
    let mut s = s;
    s.child.kill().unwrap(); // SIGKILL
    s.child.wait().unwrap();
    std::mem::forget(s);
    // Mark the first stored trial with a fidelity of 123.25 N·s/m, a field
    // a stability map never computes and that steers nothing: if the resumed
    // run replays stored trials, the mark shows in its result; recomputed,
    // it cannot.
    let rt = tokio::runtime::Runtime::new().unwrap();
    let stored_before = rt.block_on(async {
        let st = zwidth::store::Store::open(&dir.join("test.db"))
            .await
            .unwrap();
        let n = st.trial_count(&id).await.unwrap();
        st.close().await.unwrap();
        let pool =
            sqlx::SqlitePool::connect(&format!("sqlite://{}", dir.join("test.db").display()))
                .await
                .unwrap();
        let marked = sqlx::query(
            "UPDATE trials SET point = json_set(point, '$.fidelity', 123.25)
             WHERE rowid = (SELECT min(rowid) FROM trials WHERE experiment_id = ?)",
        )
        .bind(&id)
        .execute(&pool)
        .await
        .unwrap()
        .rows_affected();
        assert_eq!(marked, 1);
        pool.close().await;
        n
    });
    assert!(stored_before >= 60, "{stored_before} trials stored");
    // Restart on the same database: the run is requeued and resumes.
    let s2 = start_in(dir);
    let url = format!("{}/v1/experiments", s2.base);
    let deadline = Instant::now() + Duration::from_secs(120);
    let done = loop {
        let v = get(&format!("{url}/{id}"));
        if v["state"] == "succeeded" || v["state"] == "failed" {
            break v;
        }
        assert!(Instant::now() < deadline, "{v}");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(done["state"], "succeeded", "{done}");
    // The same result as an uninterrupted run (the library, in this process).
    let spec: zwidth::experiment::ExperimentSpec = serde_json::from_str(spec).unwrap();
    let zwidth::experiment::ExperimentSpec::Map(m) = spec else {
        unreachable!()
    };
    let want = zwidth::zwidth::search::map(&m).unwrap();
    let got = &done["result"];
    assert_eq!(got["trials"].as_u64().unwrap() as usize, want.trials);
    assert_eq!(got["k_width"].as_f64().unwrap(), want.k_width);
    assert_eq!(got["b_width"].as_f64().unwrap(), want.b_width);
    let boundary: Vec<(f64, f64)> = got["boundary"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["b"].as_f64().unwrap(), p["k_max"].as_f64().unwrap()))
        .collect();
    let want_b: Vec<(f64, f64)> = want.boundary.iter().map(|p| (p.b, p.k_max)).collect();
    assert_eq!(boundary, want_b);
    // Replayed, not recomputed: exactly one point carries the mark.
    let marked = got["points"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["fidelity"] == 123.25)
        .count();
    assert_eq!(marked, 1, "the stored trial was recomputed, not replayed");
}

#[test]
fn tokens_guard_mutations() {
    let dir = std::env::temp_dir().join(format!(
        "zwidth-svc-auth-{}-{}",
        std::process::id(),
        uuid_like()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let s = start_with(dir, &["--token", "s3cret-token-0001,other-token-00002"]);
    let url = format!("{}/v1/experiments", s.base);
    let body = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"b":[0]}"#;
    let status = |r: Result<ureq::Response, ureq::Error>| match r {
        Ok(r) => r.status(),
        Err(ureq::Error::Status(c, _)) => c,
        Err(e) => panic!("{e}"),
    };
    let post_json = |auth: Option<&str>| {
        let r = authed::post(&url).set("content-type", "application/json");
        match auth {
            Some(a) => r.set("authorization", a),
            None => r,
        }
    };
    assert_eq!(status(post_json(None).send_string(body)), 401);
    assert_eq!(
        status(post_json(Some("Bearer nope")).send_string(body)),
        403
    );
    assert_eq!(
        status(post_json(Some("Bearer other-token-00002")).send_string(body)),
        202
    );
    // Reading needs no token.
    assert_eq!(status(ureq::get(&url).call()), 200);
    // Without a token (also beyond loopback) the server makes one, owner
    // only, next to its database: no write is ever unauthenticated.
    std::fs::create_dir_all(s._dir.join("made")).unwrap();
    let s2 = start_with(s._dir.join("made"), &[]);
    let made = std::fs::read_to_string(s2._dir.join("test.db.token")).unwrap();
    assert_eq!(made.trim().len(), 48, "24 random bytes in hex");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(s2._dir.join("test.db.token"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600);
    }
    let url2 = format!("{}/v1/experiments", s2.base);
    let r = ureq::post(&url2).set("content-type", "application/json");
    assert_eq!(status(r.send_string(body)), 401);
    let r = ureq::post(&url2)
        .set("content-type", "application/json")
        .set("authorization", &format!("Bearer {}", made.trim()));
    assert_eq!(status(r.send_string(body)), 202);
}

#[test]
fn pause_schedule_metrics_and_the_cli_client() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    let body = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0]}"#;
    // Paused: nothing starts.
    let (code, v, _) = post(&format!("{}/v1/queue/pause", s.base), "");
    assert_eq!((code, v["paused"].as_bool()), (200, Some(true)));
    let (_, v, _) = post(&url, body);
    let id = v["id"].as_str().unwrap().to_string();
    // A negative observation needs a window: 400 ms, four runner rounds.
    let window = Instant::now() + Duration::from_millis(400);
    while Instant::now() < window {
        assert_eq!(get(&format!("{url}/{id}"))["state"], "queued");
        std::thread::sleep(Duration::from_millis(50));
    }
    // Scheduled far in the future: stays scheduled after resuming.
    let (code, v, _) = post(&format!("{url}?not_before_ms=99999999999999"), body);
    assert_eq!(code, 202);
    assert_eq!(v["state"], "scheduled");
    let later = v["id"].as_str().unwrap().to_string();
    post(&format!("{}/v1/queue/resume", s.base), "");
    let deadline = Instant::now() + Duration::from_secs(30);
    while get(&format!("{url}/{id}"))["state"] != "succeeded" {
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(get(&format!("{url}/{later}"))["state"], "scheduled");
    // Metrics: Prometheus text with the queue depth (the scheduled one).
    let m = ureq::get(&format!("{}/metrics", s.base))
        .call()
        .unwrap()
        .into_string()
        .unwrap();
    assert!(m.contains("zwidth_queue_depth 1"), "{m}");
    assert!(
        m.contains("zwidth_experiments{state=\"succeeded\"} 1"),
        "{m}"
    );
    assert!(m.contains("zwidth_trials_total"));
    // The CLI client against the same server.
    let file = s._dir.join("exp.json");
    std::fs::write(&file, body).unwrap();
    let run = |args: &[&str]| {
        // The client finds the token `serve` made next to its database.
        let o = Command::new(env!("CARGO_BIN_EXE_zwidth"))
            .args(args)
            .env("ZWIDTH_SERVER", &s.base)
            .env("ZWIDTH_DB", s._dir.join("test.db"))
            .env_remove("ZWIDTH_TOKEN")
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (code, out, err) = run(&["submit", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    let new_id = out.split_whitespace().next().unwrap().to_string();
    let (code, out, err) = run(&["watch", &new_id]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("succeeded"));
    let csv = s._dir.join("points.csv");
    let svg = s._dir.join("map.svg");
    let (code, _, err) = run(&[
        "results",
        &new_id,
        "--csv",
        csv.to_str().unwrap(),
        "--svg",
        svg.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(std::fs::read_to_string(&csv)
        .unwrap()
        .starts_with("map,k_n_per_m,b_ns_per_m,renders,fidelity_ns_per_m"));
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    // A bad experiment through the client: exit 2 with the server's detail.
    std::fs::write(&file, r#"{"kind":"map","scene":{"device":{"mass":0}}}"#).unwrap();
    let (code, _, err) = run(&["submit", file.to_str().unwrap()]);
    assert_eq!(code, Some(2));
    assert!(err.contains("scene.device.mass"), "{err}");
}

const LINEAR: &str =
    r#""device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}"#;

#[test]
fn rigs_windows_sweeps_comparison_and_exports() {
    let dir = std::env::temp_dir().join(format!(
        "zwidth-svc-rigs-{}-{}",
        std::process::id(),
        uuid_like()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let s = start_with(dir, &["--rigs", "sim:1,night:1"]);
    let url = format!("{}/v1/experiments", s.base);
    // The rigs, with their capabilities.
    let rigs = get(&format!("{}/v1/rigs", s.base));
    assert_eq!(rigs.as_array().unwrap().len(), 2, "{rigs}");
    assert_eq!(rigs[0]["id"], "sim");
    assert_eq!(rigs[0]["kind"], "simulator");
    assert_eq!(rigs[1]["parallelism"], 1);
    assert_eq!(rigs[1]["open_now"], true);
    // A window that opens two hours from now (UTC) keeps `night` idle.
    let now = jiff::Timestamp::now();
    let hhmm = |t: jiff::Timestamp| t.strftime("%H:%M").to_string();
    let opens = now + jiff::SignedDuration::from_hours(2);
    let window = format!(
        r#"{{"start":"{}","end":"{}","tz":"UTC"}}"#,
        hhmm(opens),
        hhmm(opens + jiff::SignedDuration::from_hours(1))
    );
    let put = |rig: &str, body: &str| {
        fetch(
            authed::put(&format!("{}/v1/rigs/{rig}/window", s.base))
                .set("content-type", "application/json")
                .send_string(body),
        )
    };
    let (code, _, text) = put("night", &window);
    assert_eq!(code, 200, "{text}");
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["open_now"], false, "{v}");
    // Opens at the start minute, within two hours and a minute from now.
    let next = v["next_start_ms"].as_i64().unwrap();
    let dt = next - now.as_millisecond();
    assert!((7_140_000..=7_200_000).contains(&dt), "{dt}");
    let (code, ct, text) = put(
        "night",
        r#"{"start":"22:00","end":"06:00","tz":"Mars/Olympus"}"#,
    );
    assert_eq!(
        (code, ct.as_str()),
        (422, "application/problem+json"),
        "{text}"
    );
    assert!(text.contains("window.tz"), "{text}");
    assert_eq!(put("nope", &window).0, 404);

    // Runs: FDM and Butterworth maps on `sim`, one map waiting on `night`.
    let map = |est: &str| {
        format!(
            r#"{{"kind":"map","scene":{{{LINEAR},"estimator":{est}}},"criterion":"strict_passivity","b":[0,5,10]}}"#
        )
    };
    let waiting = post(&format!("{url}?rig=night"), &map(r#"{"kind":"fdm"}"#)).1["id"]
        .as_str()
        .unwrap()
        .to_string();
    let fdm = post(&url, &map(r#"{"kind":"fdm"}"#)).1["id"]
        .as_str()
        .unwrap()
        .to_string();
    let bw = post(&url, &map(r#"{"kind":"butterworth","cutoff_hz":100}"#)).1["id"]
        .as_str()
        .unwrap()
        .to_string();
    // The sweep: device damping b = 1, 2, 4 N·s/m.
    let sweep = format!(
        r#"{{"kind":"sweep","map":{{"scene":{{{LINEAR}}},"criterion":"strict_passivity","b":[0]}},"parameter":{{"path":"device.damping","values":[1,2,4]}}}}"#
    );
    let (code, v, _) = post(&url, &sweep);
    assert_eq!(code, 202, "{v}");
    let sweep_id = v["id"].as_str().unwrap().to_string();
    // A compare of estimators the caller chose.
    let chosen = format!(
        r#"{{"kind":"compare","scene":{{{LINEAR}}},"accuracy":"draft","estimators":[{{"kind":"fdm"}},{{"kind":"kalman","q":1e5}}]}}"#
    );
    let (code, v, _) = post(&url, &chosen);
    assert_eq!(code, 202, "{v}");
    let chosen_id = v["id"].as_str().unwrap().to_string();
    for id in [&fdm, &bw, &sweep_id, &chosen_id] {
        assert_eq!(wait_end(&s.base, id, 60)["state"], "succeeded");
    }
    let rows = get(&format!("{url}/{chosen_id}"))["result"]["rows"].clone();
    let names: Vec<&str> = rows
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 2, "{rows}");
    assert!(
        names[0] == "fdm" && names[1].starts_with("kalman"),
        "{names:?}"
    );
    let w = get(&format!("{url}/{waiting}"));
    assert_eq!(
        (w["state"].as_str(), w["rig"].as_str()),
        (Some("queued"), Some("night")),
        "{w}"
    );
    // Strict passivity with FDM (Colgate & Schenkel): K = 2(b − |B|)/T per B.
    let sw = get(&format!("{url}/{sweep_id}"));
    for (row, want) in sw["result"]["rows"]
        .as_array()
        .unwrap()
        .iter()
        .zip([2000.0, 4000.0, 8000.0])
    {
        assert!(
            (row["k_width"].as_f64().unwrap() - want).abs() < 1e-3 * want,
            "{row}"
        );
    }
    assert_eq!(sw["progress"]["fraction"], 1.0);

    // Comparison across runs: FDM at B = 0 renders 2b/T = 26 400 N/m.
    let (code, _, text) =
        fetch(ureq::get(&format!("{}/v1/compare?runs={fdm},{bw}", s.base)).call());
    assert_eq!(code, 200, "{text}");
    let c: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(
        (c["rows"][0]["k_width"].as_f64().unwrap() - 26_400.0).abs() < 1.0,
        "{c}"
    );
    let d = c["rows"][1]["k_width"].as_f64().unwrap() - 26_400.0;
    assert!(
        (c["rows"][1]["k_width_diff"].as_f64().unwrap() - d).abs() < 1.0,
        "{c}"
    );
    assert_eq!(c["rows"][0]["k_width_diff"], 0.0);
    let (code, ct, svg) =
        fetch(ureq::get(&format!("{}/v1/compare?runs={fdm},{bw}&format=svg", s.base)).call());
    assert_eq!((code, ct.as_str()), (200, "image/svg+xml"));
    assert!(
        svg.contains("<svg") && svg.contains("butterworth(100 Hz"),
        "{}",
        &svg[..200.min(svg.len())]
    );
    let (code, _, table) = fetch(
        ureq::get(&format!(
            "{}/v1/compare?runs={fdm},{bw}&format=text",
            s.base
        ))
        .call(),
    );
    assert_eq!(code, 200);
    assert!(table.contains("K-width"), "{table}");
    // Other scenes, runs without results, bad formats: problems naming the field.
    let (code, _, text) =
        fetch(ureq::get(&format!("{}/v1/compare?runs={fdm},{sweep_id}", s.base)).call());
    assert_eq!(code, 422, "{text}");
    assert!(
        text.contains(r#""field":"runs""#) && text.contains("device"),
        "{text}"
    );
    assert_eq!(
        fetch(ureq::get(&format!("{}/v1/compare?runs={fdm},{waiting}", s.base)).call()).0,
        409
    );
    assert_eq!(
        fetch(ureq::get(&format!("{}/v1/compare?runs=", s.base)).call()).0,
        422
    );
    assert_eq!(
        fetch(ureq::get(&format!("{}/v1/compare?runs={fdm}&format=pdf", s.base)).call()).0,
        422
    );
    assert_eq!(
        fetch(ureq::get(&format!("{}/v1/compare?runs=nope", s.base)).call()).0,
        404
    );

    // Each trial, the plot and the CSV, from the server.
    let t = get(&format!("{url}/{fdm}/trials?limit=2"));
    assert_eq!(t.as_array().unwrap().len(), 2, "{t}");
    assert_eq!(t[0]["scope"], 0);
    assert_eq!(
        fetch(ureq::get(&format!("{url}/{fdm}/trials?limit=0")).call()).0,
        422
    );
    let (code, ct, svg) = fetch(ureq::get(&format!("{url}/{sweep_id}/plot.svg")).call());
    assert_eq!((code, ct.as_str()), (200, "image/svg+xml"));
    assert!(svg.contains("device.damping"));
    let (code, ct, csv) = fetch(ureq::get(&format!("{url}/{bw}/points.csv")).call());
    assert_eq!((code, ct.as_str()), (200, "text/csv"));
    assert_eq!(csv.lines().count(), 1 + 3, "{csv}");
    assert_eq!(
        fetch(ureq::get(&format!("{url}/{waiting}/plot.svg")).call()).0,
        409
    );

    // Unknown rig on submit; request ids made, or echoed when given.
    let (code, v, _) = post(&format!("{url}?rig=nope"), &map(r#"{"kind":"fdm"}"#));
    assert_eq!((code, v["field"].as_str()), (422, Some("rig")), "{v}");
    let r = ureq::get(&format!("{}/healthz", s.base)).call().unwrap();
    assert_eq!(r.header("x-request-id").map(str::len), Some(36));
    let r = ureq::get(&format!("{}/healthz", s.base))
        .set("x-request-id", "lab-42")
        .call()
        .unwrap();
    assert_eq!(r.header("x-request-id"), Some("lab-42"));

    // Clearing the window lets `night` start its experiment.
    let (code, _, _) = fetch(authed::delete(&format!("{}/v1/rigs/night/window", s.base)).call());
    assert_eq!(code, 200);
    assert_eq!(wait_end(&s.base, &waiting, 30)["state"], "succeeded");
}

#[test]
fn sigterm_interrupts_the_running_experiment_and_restart_resumes_it() {
    let spec = r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
                   "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability","search":"trace"}"#;
    let s = start();
    let dir = s._dir.clone();
    let url = format!("{}/v1/experiments", s.base);
    let id = post(&url, spec).1["id"].as_str().unwrap().to_string();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut eta_seen = false;
    loop {
        let v = get(&format!("{url}/{id}"));
        assert!(v["state"] == "running" || v["state"] == "queued", "{v}");
        eta_seen |= v["progress"]["eta_s"].as_f64().is_some_and(|e| e > 0.0);
        if v["progress"]["trials_done"].as_i64().unwrap() >= 40 && eta_seen {
            break;
        }
        assert!(Instant::now() < deadline, "{v}");
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut s = s;
    // The shell's built-in kill: present wherever `sh` is.
    let pid = s.child.id();
    assert!(Command::new("sh")
        .args(["-c", &format!("kill -TERM {pid}")])
        .status()
        .unwrap()
        .success());
    let t0 = Instant::now();
    let code = s.child.wait().unwrap();
    assert!(code.success(), "{code:?}");
    assert!(t0.elapsed() < Duration::from_secs(10));
    std::mem::forget(s);
    // The store says interrupted, with its trials kept.
    let rt = tokio::runtime::Runtime::new().unwrap();
    let row = rt.block_on(async {
        let st = zwidth::store::Store::open(&dir.join("test.db"))
            .await
            .unwrap();
        let row = st.get(&id).await.unwrap().unwrap();
        (row, st.trial_count(&id).await.unwrap())
    });
    assert_eq!(row.0.state, zwidth::store::ExperimentState::Interrupted);
    assert!(row.1 >= 40, "{} trials stored", row.1);
    // Restarted, it resumes and succeeds with the uninterrupted result.
    let s2 = start_in(dir);
    let done = wait_end(&s2.base, &id, 120);
    assert_eq!(done["state"], "succeeded", "{done}");
    let spec: zwidth::experiment::ExperimentSpec = serde_json::from_str(spec).unwrap();
    let zwidth::experiment::ExperimentSpec::Map(m) = spec else {
        unreachable!()
    };
    let want = zwidth::zwidth::search::map(&m).unwrap();
    assert_eq!(done["result"]["k_width"].as_f64().unwrap(), want.k_width);
    assert_eq!(
        done["result"]["trials"].as_u64().unwrap() as usize,
        want.trials
    );
}

#[test]
fn a_killed_tune_resumes_from_its_stored_evaluations() {
    // The auto solver, whose path depends on the budget left (grid, then
    // Brent, then a local grid): the seed device (frequency engine, draft)
    // at two damping values, cutoff 200…480 Hz in whole hertz, 8 maps.
    let spec = r#"{"kind":"tune","scene":{"loop":{"sample_hz":1000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":100}},
                   "params":{"cutoff_hz":{"min":200,"max":480,"step":1}},"objective":"k_width",
                   "max_evaluations":8,"finalists":0,"b":[0,30]}"#;
    let s = start();
    let dir = s._dir.clone();
    let url = format!("{}/v1/experiments", s.base);
    let (code, v, _) = post(&url, spec);
    assert_eq!(code, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let ev = get(&format!("{url}/{id}/evaluations"));
        let n = ev.as_array().unwrap().len();
        let v = get(&format!("{url}/{id}"));
        assert_ne!(
            v["state"], "succeeded",
            "finished before it could be killed"
        );
        if n >= 2 {
            // Best so far is shown while running.
            assert!(
                v["progress"]["best"]["params"]["cutoff_hz"]
                    .as_f64()
                    .is_some(),
                "{v}"
            );
            break;
        }
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut s = s;
    s.child.kill().unwrap();
    s.child.wait().unwrap();
    std::mem::forget(s);
    // Mark the first stored evaluation (its elapsed time only, which steers
    // nothing): the resumed result must show the mark, so it was replayed,
    // not recomputed.
    let rt = tokio::runtime::Runtime::new().unwrap();
    let stored_before = rt.block_on(async {
        let st = zwidth::store::Store::open(&dir.join("test.db"))
            .await
            .unwrap();
        let evals = st.evaluations(&id).await.unwrap();
        let mut first = evals[0].clone();
        first.record["elapsed_s"] = serde_json::json!(123.25);
        let pool =
            sqlx::SqlitePool::connect(&format!("sqlite://{}", dir.join("test.db").display()))
                .await
                .unwrap();
        sqlx::query("UPDATE evaluations SET record = ? WHERE experiment_id = ? AND key = ?")
            .bind(first.record.to_string())
            .bind(&id)
            .bind(&first.key)
            .execute(&pool)
            .await
            .unwrap();
        pool.close().await;
        st.close().await.unwrap();
        evals.len()
    });
    assert!(stored_before >= 2);
    let s2 = start_in(dir);
    let url = format!("{}/v1/experiments", s2.base);
    let done = wait_end(&s2.base, &id, 180);
    assert_eq!(done["state"], "succeeded", "{done}");
    let r = &done["result"];
    assert_eq!(
        r["history"][0]["elapsed_s"], 123.25,
        "replayed, not recomputed"
    );
    // The same path and result as an uninterrupted run in this process:
    // replayed evaluations counted toward the budget as the first time.
    let zwidth::experiment::ExperimentSpec::Tune(t) = serde_json::from_str(spec).unwrap() else {
        unreachable!()
    };
    let want = t.validate().unwrap().run(None).unwrap();
    let params = |h: &serde_json::Value| -> Vec<f64> {
        h.as_array()
            .unwrap()
            .iter()
            .map(|e| e["params"]["cutoff_hz"].as_f64().unwrap())
            .collect()
    };
    let want_params: Vec<f64> = want.history.iter().map(|e| e.params["cutoff_hz"]).collect();
    assert_eq!(params(&r["history"]), want_params);
    assert_eq!(
        r["evaluations"].as_u64().unwrap() as usize,
        want.evaluations
    );
    assert_eq!(
        r["best"]["params"]["cutoff_hz"].as_f64().unwrap(),
        want.best.params["cutoff_hz"]
    );
    assert_eq!(
        r["best"]["objectives"]["k_width"].as_f64(),
        want.best.objectives["k_width"]
    );
    // trials_done counts the replayed evaluations' trials too (defect 16).
    let trials: usize = want
        .history
        .iter()
        .filter(|e| !e.cached)
        .map(|e| e.trials)
        .sum();
    assert_eq!(
        done["progress"]["trials_done"].as_u64().unwrap() as usize,
        trials
    );
    let n_hist = want.history.len();
    let csv = fetch(ureq::get(&format!("{url}/{id}/points.csv")).call());
    assert_eq!(csv.2.lines().count(), 1 + n_hist, "{}", csv.2);
    let svg = fetch(ureq::get(&format!("{url}/{id}/plot.svg")).call());
    // The objective against the parameter: one mark per feasible
    // evaluation of the history, plus the best's ring (tune::plots).
    assert!(svg.2.contains("against cutoff_hz"), "{}", svg.2);
    let feasible = want.history.iter().filter(|e| e.feasible).count();
    assert_eq!(svg.2.matches("class=\"pt\"").count(), feasible + 1);
    // Bad tune requests are problems naming the field.
    for (body, field) in [
        (
            r#"{"kind":"tune","scene":{},"params":{"cutoff_hz":{"min":500,"max":10}},"objective":"k_width"}"#,
            "params.cutoff_hz",
        ),
        (
            r#"{"kind":"tune","scene":{"estimator":{"kind":"butterworth","cutoff_hz":100}},"params":{"q":{"min":1,"max":10}},"objective":"k_width"}"#,
            "params.q",
        ),
        (
            r#"{"kind":"tune","scene":{"estimator":{"kind":"butterworth","cutoff_hz":100}},"params":{"cutoff_hz":{"min":10,"max":100}},"objective":{"weighted":{}}}"#,
            "objective.weighted",
        ),
    ] {
        let (code, v, _) = post(&url, body);
        assert_eq!(code, 422, "{body}: {v}");
        assert!(
            v["field"].as_str().unwrap_or("").starts_with(field),
            "{body}: {v}"
        );
    }
}

#[test]
fn a_tuned_compare_reports_progress_and_its_cancel_reaches_the_tunes() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    // The seed device (friction, quantization): its tunes take minutes.
    let (code, v, _) = post(
        &url,
        r#"{"kind":"compare","accuracy":"standard","tuned":{"objective":"k_width","max_evaluations":24}}"#,
    );
    assert_eq!(code, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    // The first tune reports progress through the compare's observer.
    wait_for("the first tune's progress", 60, || {
        let v = get(&format!("{url}/{id}"));
        v["state"] == "running" && v["progress"]["fraction"].as_f64().unwrap_or(0.0) > 0.0
    });
    // Seven parts (three tunes, then four maps): the first tune alone is at
    // most 1/7 of the work.
    let f = get(&format!("{url}/{id}"))["progress"]["fraction"]
        .as_f64()
        .unwrap();
    assert!(
        f > 0.0 && f <= 1.0 / 7.0 + 1e-9,
        "fraction {f} during the first tune"
    );
    let (code, v, _) = post(&format!("{url}/{id}/cancel"), "");
    assert_eq!((code, v["state"].as_str()), (200, Some("cancelled")), "{v}");
    // The rig runs one experiment at a time: the next one finishing within
    // 30 s shows the cancel reached the running tune (uncancelled, the
    // tunes alone run for minutes, docs/zwidth.md: 8 min).
    the_rig_runs_the_next_and_the_cancelled_stays(&s.base, &id, 30);
}

/// After a cancel: a small analytic map on the same rig (one experiment at
/// a time per rig) starts and succeeds within `seconds`, and the cancelled
/// experiment stays cancelled.
fn the_rig_runs_the_next_and_the_cancelled_stays(base: &str, cancelled: &str, seconds: u64) {
    let url = format!("{base}/v1/experiments");
    let small = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"method":"analytic","criterion":"stability","b":[0,10]}"#;
    let (code, v, _) = post(&url, small);
    assert_eq!(code, 202, "{v}");
    let next = wait_end(base, v["id"].as_str().unwrap(), seconds);
    assert_eq!(next["state"], "succeeded", "{next}");
    assert_eq!(get(&format!("{url}/{cancelled}"))["state"], "cancelled");
}

/// The same map with an automatic B range on rigs of 1 and 3 threads
/// (issue 14): the same stored trials in the same order, ending at the
/// first two empty columns; columns a batch ran past that are not stored.
#[test]
fn an_automatic_map_stores_the_same_trials_on_any_thread_count() {
    // The analytic 2018 device: B = 0 … 1000 render, 1100 and 1200 do not
    // (the library's own column-by-column check in zwidth-core's search
    // tests): 13 columns, which batches of 3 overshoot.
    let spec = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},
                  "method":"analytic","b_max":5000,"k_max":1e6,"accuracy":{"preset":"draft","b_step":100}}"#;
    let mut seen: Vec<serde_json::Value> = Vec::new();
    for rigs in ["sim:1", "sim:3"] {
        let dir =
            std::env::temp_dir().join(format!("zwidth-threads-{}-{}", &rigs[4..], uuid_like()));
        std::fs::create_dir_all(&dir).unwrap();
        let s = start_with(dir, &["--rigs", rigs]);
        let (code, v, _) = post(&format!("{}/v1/experiments", s.base), spec);
        assert_eq!(code, 202, "{v}");
        let id = v["id"].as_str().unwrap();
        let done = wait_end(&s.base, id, 60);
        assert_eq!(done["state"], "succeeded", "{done}");
        let stored = get(&format!(
            "{}/v1/experiments/{id}/trials?limit=10000",
            s.base
        ));
        let stored = stored.as_array().unwrap();
        let points: Vec<&serde_json::Value> = stored.iter().map(|t| &t["point"]).collect();
        let want: Vec<&serde_json::Value> = done["result"]["points"]
            .as_array()
            .unwrap()
            .iter()
            .collect();
        assert_eq!(
            points, want,
            "{rigs}: stored trials are the result's points, in order"
        );
        let last_column = stored.iter().map(|t| t["column"].as_u64().unwrap()).max();
        assert_eq!(last_column, Some(12), "{rigs}");
        seen.push(serde_json::Value::Array(stored.to_vec()));
    }
    assert_eq!(seen[0], seen[1]);
}

/// One raw HTTP/1.1 GET of `path` with `Host: host`: (status, body).
fn raw_get(base: &str, host: &str, path: &str) -> (u16, String) {
    use std::io::{Read, Write};
    let addr = base.trim_start_matches("http://");
    let mut c = std::net::TcpStream::connect(addr).unwrap();
    write!(
        c,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut text = String::new();
    c.read_to_string(&mut text).unwrap();
    let status = text[9..12].parse().unwrap();
    (status, text)
}

/// Issue 45 item 5: bound beyond loopback, every read needs the token (the
/// dashboard asks once and keeps it in an HttpOnly, SameSite=Strict
/// cookie); `--reads public` opens them again; every request's Host must
/// name this server (a DNS-rebinding page's own name gets 421).
#[test]
#[allow(clippy::result_large_err)] // ureq's error, as every ureq call returns
fn reads_are_private_beyond_loopback_and_the_host_is_checked() {
    let dir = std::env::temp_dir().join(format!(
        "zwidth-reads-{}-{}",
        std::process::id(),
        uuid_like()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let s = start_on(dir.clone(), "0.0.0.0:0", &["--host", "zwidth.lab.example"]);
    let token = token_for(&s.base).unwrap();
    let list = format!("{}/v1/experiments", s.base);
    let status = |r: Result<ureq::Response, ureq::Error>| fetch(r).0;
    // The API: 401 problem+json without the token, 200 with it.
    match ureq::get(&list).call() {
        Err(ureq::Error::Status(401, r)) => {
            assert_eq!(r.content_type(), "application/problem+json");
            let v: serde_json::Value = r.into_json().unwrap();
            assert_eq!(v["field"], "Authorization", "{v}");
        }
        other => panic!("{other:?}"),
    }
    let bearer = format!("Bearer {token}");
    assert_eq!(
        status(ureq::get(&list).set("authorization", &bearer).call()),
        200
    );
    // Open: the health check.
    assert_eq!(
        status(ureq::get(&format!("{}/healthz", s.base)).call()),
        200
    );
    // The dashboard: to the sign-in page, which returns here, then the
    // cookie.
    let no_redirects = ureq::AgentBuilder::new().redirects(0).build();
    let r = no_redirects
        .get(&format!("{}/runs", s.base))
        .call()
        .unwrap();
    assert_eq!(
        (r.status(), r.header("location")),
        (303, Some("/login?next=%2Fruns"))
    );
    let html = ureq::get(&format!("{}/login?next=%2Fruns", s.base))
        .call()
        .unwrap()
        .into_string()
        .unwrap();
    assert!(
        html.contains("action=\"/login\"") && html.contains("value=\"/runs\""),
        "{html}"
    );
    let login = |t: &str| {
        no_redirects
            .post(&format!("{}/login", s.base))
            .set("origin", &s.base)
            .set("content-type", "application/x-www-form-urlencoded")
            .send_string(&format!("token={t}&next=%2Fruns"))
    };
    assert_eq!(status(login("wrong")), 403);
    let r = login(&token).unwrap();
    assert_eq!((r.status(), r.header("location")), (303, Some("/runs")));
    let cookie = r.header("set-cookie").unwrap().to_string();
    // A week, as docs/service.md says: 7 × 24 × 3600 s.
    for attr in ["HttpOnly", "SameSite=Strict", "Path=/", "Max-Age=604800"] {
        assert!(cookie.contains(attr), "{cookie}");
    }
    let pair = cookie.split(';').next().unwrap().to_string();
    assert_eq!(
        status(
            ureq::get(&format!("{}/runs", s.base))
                .set("cookie", &pair)
                .call()
        ),
        200
    );
    assert_eq!(status(ureq::get(&list).set("cookie", &pair).call()), 200);
    // The cookie opens reads, never writes.
    let w = ureq::post(&format!("{}/v1/queue/pause", s.base))
        .set("cookie", &pair)
        .call();
    assert_eq!(status(w), 401);
    // The Host: this server's names and any IP address; not another name.
    assert_eq!(
        raw_get(&s.base, "zwidth.lab.example:8080", "/healthz").0,
        200
    );
    assert_eq!(raw_get(&s.base, "ZWIDTH.LAB.EXAMPLE", "/healthz").0, 200);
    assert_eq!(raw_get(&s.base, "10.1.2.3:8080", "/healthz").0, 200);
    assert_eq!(raw_get(&s.base, "[::1]:8080", "/healthz").0, 200);
    let (code, text) = raw_get(&s.base, "rebind.evil.example:8080", "/v1/experiments");
    assert_eq!(code, 421, "{text}");
    assert!(text.contains("\"field\":\"Host\""), "{text}");
    drop(s);
    // `--reads public` beyond loopback: reads are open again.
    let dir = std::env::temp_dir().join(format!(
        "zwidth-reads-{}-{}",
        std::process::id(),
        uuid_like()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let s = start_on(dir, "0.0.0.0:0", &["--reads", "public"]);
    assert_eq!(
        status(ureq::get(&format!("{}/v1/experiments", s.base)).call()),
        200
    );
    // On loopback (every other test's server) reads are open by default,
    // and the Host is checked there too.
    let s = start();
    assert_eq!(
        status(ureq::get(&format!("{}/v1/experiments", s.base)).call()),
        200
    );
    assert_eq!(
        raw_get(&s.base, "rebind.evil.example", "/v1/experiments").0,
        421
    );
}
