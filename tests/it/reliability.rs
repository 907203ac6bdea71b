//! Reliability under attack and faults (issue 9): each test names the
//! defect it guards against, and fails on the code that had it.

use crate::common::*;

use std::process::Command;
use std::time::{Duration, Instant};

fn temp_dir(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "zwidth-rel-{tag}-{}-{}",
        std::process::id(),
        uuid_like()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Any request: status, content type, body as JSON (Null when not JSON).
fn call(r: Result<ureq::Response, ureq::Error>) -> (u16, String, serde_json::Value) {
    let (code, ct, text) = fetch(r);
    (code, ct, serde_json::from_str(&text).unwrap_or_default())
}

fn post_json(url: &str) -> ureq::Request {
    authed::post(url).set("content-type", "application/json")
}

fn assert_problem(code: u16, ct: &str, v: &serde_json::Value, want: u16, field: Option<&str>) {
    assert_eq!(code, want, "{v}");
    assert_eq!(ct, "application/problem+json", "{v}");
    assert_eq!(v["status"], want, "{v}");
    if let Some(f) = field {
        assert_eq!(v["field"], f, "{v}");
    }
}

const LINEAR: &str = include_str!("../../examples/linear_1khz.json");

/// The cheapest experiment: one exact strict-passivity column of the 2018
/// device without friction and quantization, single rate (milliseconds).
const SMALL: &str = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0]}"#;

/// Defects 1 and 5: accepted specs whose cost has no bound. Each is a 422
/// naming the field now; before, 202 and a server that aborted (b_max) or
/// ran without end (k_rel_tol, k_step).
#[test]
fn specs_beyond_the_cost_limits_are_refused_naming_the_field() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    let scene: serde_json::Value = serde_json::from_str(LINEAR).unwrap();
    let map = |extra: serde_json::Value| {
        let mut m = serde_json::json!({"kind": "map", "scene": scene.clone()});
        for (k, v) in extra.as_object().unwrap() {
            m[k] = v.clone();
        }
        m.to_string()
    };
    for (body, field) in [
        (map(serde_json::json!({"b_max": 1e15})), "b_max"),
        (
            map(serde_json::json!({"accuracy": {"b_step": 1e-9}})),
            "accuracy.b_step",
        ),
        (
            map(serde_json::json!({"accuracy": {"k_rel_tol": 1e-300}})),
            "accuracy.k_rel_tol",
        ),
        (
            map(serde_json::json!({"search": "trace", "accuracy": {"k_step": 1e-3}})),
            "accuracy.k_step",
        ),
        (map(serde_json::json!({"b": vec![1.0; 2001]})), "b"),
    ] {
        let (code, ct, v) = call(post_json(&url).send_string(&body));
        assert_problem(code, &ct, &v, 422, Some(field));
    }
    // A tune whose maps together plan too many trials names its budget.
    let mut bw = scene.clone();
    bw["estimator"] = serde_json::json!({"kind": "butterworth", "cutoff_hz": 100});
    let tune = serde_json::json!({"kind": "tune", "scene": bw, "params": {"cutoff_hz": {"min": 10, "max": 400}},
        "objective": "k_width", "search": "trace", "accuracy": "reference", "max_evaluations": 5000}).to_string();
    let (code, ct, v) = call(post_json(&url).send_string(&tune));
    assert_problem(code, &ct, &v, 422, Some("max_evaluations"));
    // A compare takes 1 to 20 estimators (validated before anything runs).
    call(authed::post(&format!("{}/v1/queue/pause", s.base)).call());
    let est = |n: usize| {
        serde_json::json!({"kind": "compare", "accuracy": "draft",
            "estimators": vec![serde_json::json!({"kind": "fdm"}); n]})
        .to_string()
    };
    let (code, ct, v) = call(post_json(&url).send_string(&est(21)));
    assert_problem(code, &ct, &v, 422, Some("estimators"));
    let (code, ct, v) = call(post_json(&url).send_string(&est(0)));
    assert_problem(code, &ct, &v, 422, Some("estimators"));
    let (code, _, v) = call(post_json(&url).send_string(&est(20)));
    assert_eq!(code, 202, "{v}");
    assert_eq!(v["estimate"]["maps"], 20, "{v}");
    // Accepted requests say what they will cost.
    let ok = map(serde_json::json!({"b": [0, 5], "criterion": "strict_passivity"}));
    let (code, _, v) = call(post_json(&url).send_string(&ok));
    assert_eq!(code, 202, "{v}");
    assert_eq!(v["kind"], "map", "{v}");
    assert_eq!(v["estimate"]["trials"], 2, "{v}");
    assert_eq!(v["estimate"]["b_columns"], 2, "{v}");
    // Nothing but the good ones was stored.
    let all = get(&url);
    assert_eq!(all["experiments"].as_array().unwrap().len(), 2, "{all}");
}

/// Every documented guard and limit (docs/service.md, "Limits" and
/// "Browser writes and tokens"): the status and the field it names, one row
/// each; a value at the limit is accepted where that is cheap to show.
#[test]
fn every_documented_limit_answers_its_status_and_field() {
    let dir = temp_dir("limits");
    let s = start_with(dir, &["--token", "reliability-token-16"]);
    let url = format!("{}/v1/experiments", s.base);
    let authed = |u: &str| {
        authed::post(u)
            .set("content-type", "application/json")
            .set("authorization", "Bearer reliability-token-16")
    };
    // Nothing runs: only validation is under test.
    let (code, _, v) = call(authed(&format!("{}/v1/queue/pause", s.base)).send_string(""));
    assert_eq!(code, 200, "{v}");
    let scene: serde_json::Value = serde_json::from_str(LINEAR).unwrap();
    let with_scene = |patch: serde_json::Value| {
        let mut sc = scene.clone();
        for (k, v) in patch.as_object().unwrap() {
            sc[k] = v.clone();
        }
        serde_json::json!({"kind": "map", "scene": sc, "b": [0]}).to_string()
    };
    let sweep = |n: usize| {
        serde_json::json!({"kind": "sweep", "map": {"scene": scene.clone(), "b": [0], "criterion": "strict_passivity"},
            "parameter": {"path": "device.mass", "values": (1..=n).map(|i| 0.1 * i as f64).collect::<Vec<_>>()}})
        .to_string()
    };
    for (body, want, field) in [
        // Probe lines: f_max_hz / f_min_hz ≤ 1 000.
        (
            with_scene(serde_json::json!({"probe": {"f_min_hz": 1, "f_max_hz": 1001}})),
            422,
            "scene.probe.f_max_hz",
        ),
        // Steps per probe period ≤ 4e6: a 0.2 Hz period at 1 MHz is 5e6.
        (
            with_scene(
                serde_json::json!({"loop": {"sample_hz": 1_000_000, "render_hz": 1000}, "probe": {"f_min_hz": 0.2, "f_max_hz": 100}}),
            ),
            422,
            "scene.probe.f_min_hz",
        ),
        // Samples per wall hit ≤ 1e9: 3 600 s at 1 MHz.
        (
            with_scene(
                serde_json::json!({"loop": {"sample_hz": 1_000_000, "render_hz": 1000}, "hit": {"settle_s": 1800, "measure_s": 1800}}),
            ),
            422,
            "scene.hit.measure_s",
        ),
        // Sweep variants ≤ 200.
        (sweep(201), 422, "parameter.values"),
    ] {
        let (code, ct, v) = call(authed(&url).send_string(&body));
        assert_problem(code, &ct, &v, want, Some(field));
    }
    let (code, _, v) = call(authed(&url).send_string(&sweep(200)));
    assert_eq!(code, 202, "200 variants are allowed: {v}");
    let id = v["id"].as_str().unwrap().to_string();
    // Runs per comparison ≤ 50 distinct ids, counted before any is looked
    // up: 51 unknown ids are refused as too many, 50 as unknown (404).
    let runs = |n: usize| {
        (0..n)
            .map(|i| format!("r{i}"))
            .collect::<Vec<_>>()
            .join(",")
    };
    let (code, ct, v) = call(ureq::get(&format!("{}/v1/compare?runs={}", s.base, runs(51))).call());
    assert_problem(code, &ct, &v, 422, Some("runs"));
    let (code, ct, v) = call(ureq::get(&format!("{}/v1/compare?runs={}", s.base, runs(50))).call());
    assert_problem(code, &ct, &v, 404, None);
    let (code, ct, v) = call(ureq::get(&format!("{}/v1/compare?runs=", s.base)).call());
    assert_problem(code, &ct, &v, 422, Some("runs"));
    // Pages: a list page ≤ 200, a trial page ≤ 10 000.
    for (q, ok) in [("limit=200", true), ("limit=201", false)] {
        let (code, ct, v) = call(ureq::get(&format!("{url}?{q}")).call());
        if ok {
            assert_eq!(code, 200, "{v}");
        } else {
            assert_problem(code, &ct, &v, 422, Some("limit"));
        }
    }
    for (q, ok) in [
        ("limit=10000", true),
        ("limit=10001", false),
        ("limit=0", false),
    ] {
        let (code, ct, v) = call(ureq::get(&format!("{url}/{id}/trials?{q}")).call());
        if ok {
            assert_eq!(code, 200, "{v}");
        } else {
            assert_problem(code, &ct, &v, 422, Some("limit"));
        }
    }
    // The body: 1 MiB → 413.
    let big = format!(r#"{{"kind":"map","pad":"{}"}}"#, "x".repeat(1 << 20));
    let (code, ct, v) = call(authed(&url).send_string(&big));
    assert_problem(code, &ct, &v, 413, Some("body"));
    // Auth on every write route: 401 naming Authorization without a token,
    // 403 with a wrong one; the same request with the token gets past it.
    let rig = get(&format!("{}/v1/rigs", s.base))[0]["id"]
        .as_str()
        .unwrap()
        .to_string();
    let window = r#"{"start":"22:00","end":"06:00","tz":"UTC"}"#;
    let routes: Vec<(&str, String, &str)> = vec![
        ("POST", url.clone(), SMALL),
        ("POST", format!("{url}/{id}/cancel"), ""),
        ("POST", format!("{}/v1/queue/pause", s.base), ""),
        ("POST", format!("{}/v1/queue/resume", s.base), ""),
        ("PUT", format!("{}/v1/rigs/{rig}/window", s.base), window),
        ("DELETE", format!("{}/v1/rigs/{rig}/window", s.base), ""),
    ];
    for (method, u, body) in &routes {
        let req = |auth: Option<&str>| {
            let r = ureq::request(method, u).set("content-type", "application/json");
            match auth {
                Some(a) => r.set("authorization", a),
                None => r,
            }
        };
        let (code, ct, v) = call(req(None).send_string(body));
        assert_problem(code, &ct, &v, 401, Some("Authorization"));
        let (code, ct, v) = call(req(Some("Bearer wrong")).send_string(body));
        assert_problem(code, &ct, &v, 403, Some("Authorization"));
        let (code, _, v) = call(req(Some("Bearer reliability-token-16")).send_string(body));
        assert!((200..300).contains(&code), "{method} {u}: {code} {v}");
    }
}

/// Defect 1, the crash loop: a spec stored by an older version that today's
/// limits refuse fails with the reason when its turn comes; the server runs on.
#[test]
fn a_stored_spec_beyond_the_limits_fails_instead_of_taking_the_server_down() {
    let dir = temp_dir("stored");
    let rt = tokio::runtime::Runtime::new().unwrap();
    let spec = format!(r#"{{"kind":"map","scene":{LINEAR},"b_max":1e15}}"#).replace('\n', "");
    rt.block_on(async {
        let st = zwidth::store::Store::open(&dir.join("test.db"))
            .await
            .unwrap();
        st.insert(zwidth::store::NewExperiment::queued(
            "old-1", "map", &spec, "sim",
        ))
        .await
        .unwrap();
        st.close().await.unwrap();
    });
    let s = start_in(dir);
    let done = wait_end(&s.base, "old-1", 30);
    assert_eq!(done["state"], "failed", "{done}");
    assert!(done["error"].as_str().unwrap().contains("b_max"), "{done}");
    assert_eq!(get(&format!("{}/healthz", s.base))["status"], "ok");
}

/// An experiment whose stored trials cannot be read (here their table is
/// gone: a permanent fault, not a busy database) fails saying so, at once,
/// and the server goes on.
#[test]
fn stored_work_that_cannot_be_read_fails_the_experiment_saying_so() {
    let dir = temp_dir("unreadable");
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let st = zwidth::store::Store::open(&dir.join("test.db"))
            .await
            .unwrap();
        st.insert(zwidth::store::NewExperiment::queued(
            "unreadable-1",
            "map",
            SMALL,
            "sim",
        ))
        .await
        .unwrap();
        st.close().await.unwrap();
        use sqlx::Connection;
        let url = format!("sqlite://{}", dir.join("test.db").display());
        let mut c = sqlx::SqliteConnection::connect(&url).await.unwrap();
        sqlx::query("ALTER TABLE trials RENAME TO trials_gone")
            .execute(&mut c)
            .await
            .unwrap();
        c.close().await.unwrap();
    });
    let s = start_in(dir);
    let done = wait_end(&s.base, "unreadable-1", 10);
    assert_eq!(done["state"], "failed", "{done}");
    assert!(
        done["error"]
            .as_str()
            .unwrap()
            .starts_with("its stored trials could not be read"),
        "{done}"
    );
    assert_eq!(get(&format!("{}/healthz", s.base))["status"], "ok");
}

/// Defect 7: one Idempotency-Key, many concurrent submissions: one
/// experiment, every answer names it, no 500. A different body under the
/// same key is a 422 naming the key.
#[test]
fn concurrent_submissions_with_one_key_store_one_experiment() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    // Pause so nothing runs while we count.
    call(authed::post(&format!("{}/v1/queue/pause", s.base)).call());
    let body = SMALL;
    let answers: Vec<(u16, serde_json::Value)> = std::thread::scope(|sc| {
        let hs: Vec<_> = (0..32)
            .map(|_| {
                sc.spawn(|| {
                    let (c, _, v) = call(
                        post_json(&url)
                            .set("idempotency-key", "same-key")
                            .send_string(body),
                    );
                    (c, v)
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let created = answers.iter().filter(|(c, _)| *c == 202).count();
    assert_eq!(created, 1, "{answers:?}");
    assert!(
        answers.iter().all(|(c, _)| *c == 202 || *c == 200),
        "{answers:?}"
    );
    let id = &answers[0].1["id"];
    assert!(answers.iter().all(|(_, v)| &v["id"] == id), "{answers:?}");
    assert_eq!(get(&url)["experiments"].as_array().unwrap().len(), 1);
    let other = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[5]}"#;
    let (code, ct, v) = call(
        post_json(&url)
            .set("idempotency-key", "same-key")
            .send_string(other),
    );
    assert_problem(code, &ct, &v, 422, Some("Idempotency-Key"));
}

/// Defect 9: a finish that cannot be written while another writer holds
/// the lock is retried; the experiment ends once the lock is released,
/// with every trial stored.
#[test]
fn a_finish_blocked_by_a_held_lock_is_retried() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    // A time-domain trace of about two seconds (1 600 trials at 10 kHz).
    let body = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":10000,"render_hz":1000}},"method":"time","criterion":"stability","search":"trace"}"#;
    let (code, _, v) = call(post_json(&url).send_string(body));
    assert_eq!(code, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    // Lock only once it runs (a claim blocked by the lock would just wait),
    // and longer than the run plus the 5 s busy timeout, so its end is
    // written while the lock is held.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let v = get(&format!("{url}/{id}"));
        match v["state"].as_str() {
            Some("running") => break,
            Some("queued") => {}
            _ => panic!("ended before the lock could be taken: {v}"),
        }
        assert!(Instant::now() < deadline, "{v}");
        std::thread::sleep(Duration::from_millis(5));
    }
    let db = s._dir.join("test.db");
    let rt = tokio::runtime::Runtime::new().unwrap();
    let hold = Duration::from_secs(20);
    let held_at = Instant::now();
    rt.block_on(async {
        use sqlx::Connection;
        let mut c = sqlx::SqliteConnection::connect(&format!("sqlite://{}", db.display()))
            .await
            .unwrap();
        sqlx::query("BEGIN IMMEDIATE")
            .execute(&mut c)
            .await
            .unwrap();
        tokio::time::sleep(hold).await;
        // Reads go on meanwhile (WAL).
        sqlx::query("ROLLBACK").execute(&mut c).await.unwrap();
    });
    assert!(held_at.elapsed() >= hold);
    let done = wait_end(&s.base, &id, 30);
    assert_eq!(done["state"], "succeeded", "{done}");
    let stored = get(&format!("{url}/{id}/trials?limit=10000"));
    assert_eq!(
        stored.as_array().unwrap().len() as u64,
        done["result"]["trials"].as_u64().unwrap()
    );
}

/// Defect 4: the list is paged and leaves results out unless asked.
#[test]
fn the_list_is_paged_with_a_cursor() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    call(authed::post(&format!("{}/v1/queue/pause", s.base)).call());
    let body = SMALL;
    let mut ids = Vec::new();
    for _ in 0..5 {
        let (_, _, v) = call(post_json(&url).send_string(body));
        ids.push(v["id"].as_str().unwrap().to_string());
    }
    let mut seen = Vec::new();
    let mut next = format!("{url}?limit=2");
    loop {
        let page = get(&next);
        for e in page["experiments"].as_array().unwrap() {
            assert!(e.get("spec").is_none() && e.get("result").is_none(), "{e}");
            seen.push(e["id"].as_str().unwrap().to_string());
        }
        match page["next_cursor"].as_str() {
            Some(c) => next = format!("{url}?limit=2&cursor={c}"),
            None => break,
        }
    }
    ids.reverse(); // newest first
    assert_eq!(seen, ids);
    let with_spec = get(&format!("{url}?limit=1&include=spec"));
    assert_eq!(with_spec["experiments"][0]["spec"]["kind"], "map");
    for (q, field) in [
        ("limit=0", "limit"),
        ("limit=201", "limit"),
        ("limit=21&include=result", "limit"),
        ("include=everything", "include"),
        ("cursor=zzz", "cursor"),
        ("page=2", "page"),
    ] {
        let (code, ct, v) = call(ureq::get(&format!("{url}?{q}")).call());
        assert_problem(code, &ct, &v, 422, Some(field));
    }
}

/// Defect 6: a page on another site cannot make the operator's browser
/// write: form-encoded bodies are 415; a foreign Origin, a cross-site fetch
/// are 403, for every write (a DNS-rebinding page naming its own Host
/// has no token: 401).
#[test]
fn writes_from_other_sites_are_refused() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    let body = SMALL;
    let (code, ct, v) = call(
        authed::post(&url)
            .set("content-type", "text/plain")
            .send_string(body),
    );
    assert_problem(code, &ct, &v, 415, Some("Content-Type"));
    let (code, ct, v) = call(authed::post(&url).send_string(body));
    assert_problem(code, &ct, &v, 415, Some("Content-Type"));
    let pause = format!("{}/v1/queue/pause", s.base);
    for (header, value, field) in [
        ("origin", "http://evil.example", "Origin"),
        ("origin", "null", "Origin"),
        ("sec-fetch-site", "cross-site", "Sec-Fetch-Site"),
    ] {
        let (code, ct, v) = call(post_json(&url).set(header, value).send_string(body));
        assert_problem(code, &ct, &v, 403, Some(field));
        let (code, ct, v) = call(authed::post(&pause).set(header, value).call());
        assert_problem(code, &ct, &v, 403, Some(field));
    }
    // A foreign Host (a DNS-rebinding page), token or not: 421 naming the
    // Host (before issue 45: 401 without the token, accepted with it).
    for r in [ureq::post(&url), authed::post(&url)] {
        let (code, ct, v) = call(
            r.set("content-type", "application/json")
                .set("host", "evil.example")
                .send_string(body),
        );
        assert_problem(code, &ct, &v, 421, Some("Host"));
    }
    assert_eq!(get(&format!("{}/v1/queue", s.base))["paused"], false);
    assert_eq!(get(&url)["experiments"].as_array().unwrap().len(), 0);
    // The server's own origin may write.
    let own = s.base.clone();
    let (code, _, v) = call(post_json(&url).set("origin", &own).send_string(body));
    assert_eq!(code, 202, "{v}");
    // An origin given with --allow-origin may too (a reverse proxy's), and
    // only that one.
    let s2 = start_with(
        temp_dir("allow"),
        &["--allow-origin", "https://lab.example"],
    );
    let url2 = format!("{}/v1/experiments", s2.base);
    let (code, _, v) = call(
        post_json(&url2)
            .set("origin", "https://lab.example")
            .set("sec-fetch-site", "same-site")
            .send_string(body),
    );
    assert_eq!(code, 202, "{v}");
    let (code, ct, v) = call(
        post_json(&url2)
            .set("origin", "https://other.example")
            .send_string(body),
    );
    assert_problem(code, &ct, &v, 403, Some("Origin"));
}

/// One server per database: a second `zwidth serve` on the same database
/// is refused (two would run the same experiments twice).
#[test]
fn a_second_server_on_one_database_is_refused() {
    let s = start();
    let o = Command::new(bin())
        .args(["serve", "--bind", "127.0.0.1:0", "--db"])
        .arg(s._dir.join("test.db"))
        .env_remove("ZWIDTH_TOKENS")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("another zwidth serve"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The first one serves on.
    assert_eq!(get(&format!("{}/healthz", s.base))["status"], "ok");
}

/// Defect 11: every error is problem+json, with the field where there is
/// one, including the framework's own rejections.
#[test]
fn every_error_is_a_problem_naming_the_field() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    let good = SMALL;
    // Bad query values.
    let (code, ct, v) = call(post_json(&format!("{url}?priority=abc")).send_string(good));
    assert_problem(code, &ct, &v, 422, Some("priority"));
    let (code, ct, v) = call(ureq::get(&format!("{url}/x/trials?limit=abc")).call());
    assert_problem(code, &ct, &v, 422, Some("limit"));
    // A body over 1 MiB.
    let big = format!(r#"{{"kind":"map","pad":"{}"}}"#, "x".repeat(1 << 20));
    let (code, ct, v) = call(post_json(&url).send_string(&big));
    assert_problem(code, &ct, &v, 413, Some("body"));
    // JSON errors name the path.
    let bad = r#"{"kind":"map","scene":{"device":{"mass":"heavy"}}}"#;
    let (code, ct, v) = call(post_json(&url).send_string(bad));
    assert_problem(code, &ct, &v, 422, Some("scene.device.mass"));
    let bad = r#"{"kind":"map","scene":{},"bogus":1}"#;
    let (code, ct, v) = call(post_json(&url).send_string(bad));
    assert_problem(code, &ct, &v, 422, Some("bogus"));
    let (code, ct, v) = call(post_json(&url).send_string("{"));
    assert_problem(code, &ct, &v, 422, Some("body"));
    let trailing = format!("{good} and more");
    let (code, ct, v) = call(post_json(&url).send_string(&trailing));
    assert_problem(code, &ct, &v, 422, Some("body"));
    // A bad escape in the path, a very long query, unknown routes and methods.
    let (code, ct, v) = call(ureq::get(&format!("{url}/%FF%FE")).call());
    assert_problem(code, &ct, &v, 400, Some("id"));
    let long = format!("{}/v1/compare?runs={}", s.base, "a,".repeat(10_000));
    let (code, ct, v) = call(ureq::get(&long).call());
    assert_problem(code, &ct, &v, 414, Some("query"));
    let (code, ct, _) = call(ureq::get(&format!("{}/v1/nothing", s.base)).call());
    assert_eq!((code, ct.as_str()), (404, "application/problem+json"));
    let (code, ct, _) = call(authed::delete(&url).call());
    assert_eq!((code, ct.as_str()), (405, "application/problem+json"));
}

/// Defect 10: inputs that would overflow are refused naming the field;
/// the CLI exits 2 instead of printing inf or NaN.
#[test]
fn overflowing_inputs_are_refused() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    let tune = r#"{"kind":"tune","scene":{"device":{"coulomb":0,"quantization":0},"estimator":{"kind":"butterworth","cutoff_hz":100}},
        "params":{"cutoff_hz":{"min":20,"max":400}},"objective":{"weighted":{"k_width":1e308}},"b":[0]}"#;
    let (code, ct, v) = call(post_json(&url).send_string(tune));
    assert_problem(code, &ct, &v, 422, Some("objective.weighted.k_width"));
    let zw = |args: &[&str], stdin: &str| {
        use std::io::Write;
        let mut c = Command::new(bin())
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        c.stdin.take().unwrap().write_all(stdin.as_bytes()).unwrap();
        let o = c.wait_with_output().unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (code, out, err) = zw(
        &["lipschitz", "--rate", "1000"],
        "0\n1e308\n-1e308\n0\n0\n0\n",
    );
    assert_eq!(code, Some(2), "{out}{err}");
    assert!(err.contains("positions[1]"), "{err}");
    let (code, out, err) = zw(
        &[
            "gains",
            "--estimator",
            r#"{"kind":"levant","alpha":1e308,"lambda":1e308,"lipschitz":1e-308}"#,
        ],
        "",
    );
    assert_eq!(code, Some(2), "{out}{err}");
    assert!(!out.contains("inf") && !out.contains("NaN"), "{out}");
}

/// Defect 12: a corrupt database is reported by /healthz and refuses
/// writes with a clear error, instead of "ok" and 500s.
#[test]
fn a_corrupt_database_is_reported_and_refuses_writes() {
    let dir = temp_dir("corrupt");
    let db = dir.join("test.db");
    let rt = tokio::runtime::Runtime::new().unwrap();
    let (page, root) = rt.block_on(async {
        let st = zwidth::store::Store::open(&db).await.unwrap();
        for i in 0..50 {
            st.insert(zwidth::store::NewExperiment::queued(
                &format!("e{i}"),
                "map",
                &"x".repeat(500),
                "sim",
            ))
            .await
            .unwrap();
        }
        st.close().await.unwrap();
        let pool = sqlx::SqlitePool::connect(&format!("sqlite://{}", db.display()))
            .await
            .unwrap();
        let page: i64 = sqlx::query_scalar("PRAGMA page_size")
            .fetch_one(&pool)
            .await
            .unwrap();
        let root: i64 =
            sqlx::query_scalar("SELECT rootpage FROM sqlite_schema WHERE name = 'experiments'")
                .fetch_one(&pool)
                .await
                .unwrap();
        pool.close().await;
        (page as u64, root as u64)
    });
    // Garble the experiments table's root page (not the schema, page 1).
    {
        use std::io::{Seek, SeekFrom, Write};
        let mut f = std::fs::OpenOptions::new().write(true).open(&db).unwrap();
        f.seek(SeekFrom::Start((root - 1) * page + 8)).unwrap();
        f.write_all(&vec![0xA5u8; page as usize - 8]).unwrap();
    }
    let s = start_in(dir);
    let (code, _, v) = call(ureq::get(&format!("{}/healthz", s.base)).call());
    assert_eq!(code, 503, "{v}");
    assert_eq!(v["status"], "corrupt", "{v}");
    let body = SMALL;
    let url = format!("{}/v1/experiments", s.base);
    let (code, ct, v) = call(post_json(&url).send_string(body));
    assert_problem(code, &ct, &v, 503, None);
    assert!(v["detail"].as_str().unwrap().contains("corrupt"), "{v}");
}

/// Defect 14: a cleanly stopped server leaves a complete `.db` (no data
/// left in the WAL), and `zwidth backup` copies a live database.
#[test]
fn shutdown_checkpoints_and_backup_copies_a_live_database() {
    let s = start();
    let dir = s._dir.clone();
    let url = format!("{}/v1/experiments", s.base);
    let body = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0,5]}"#;
    let (_, _, v) = call(post_json(&url).send_string(body));
    let id = v["id"].as_str().unwrap().to_string();
    wait_end(&s.base, &id, 30);
    // Backup while it serves.
    let copy = dir.join("copy.db");
    let o = Command::new(bin())
        .args(["backup", "--db"])
        .arg(dir.join("test.db"))
        .arg("--out")
        .arg(&copy)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Backing up onto an existing file is bad input.
    let o = Command::new(bin())
        .args(["backup", "--db"])
        .arg(dir.join("test.db"))
        .arg("--out")
        .arg(&copy)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    // SIGTERM, then the .db alone (copied without its -wal) has the run.
    let mut s = s;
    assert!(Command::new("sh")
        .args(["-c", &format!("kill -TERM {}", s.child.id())])
        .status()
        .unwrap()
        .success());
    assert!(s.child.wait().unwrap().success());
    std::mem::forget(s);
    let alone = temp_dir("alone");
    std::fs::copy(dir.join("test.db"), alone.join("only.db")).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    for db in [alone.join("only.db"), copy] {
        let state = rt.block_on(async {
            let pool = sqlx::SqlitePool::connect(&format!("sqlite://{}?mode=ro", db.display()))
                .await
                .unwrap();
            let st: String = sqlx::query_scalar("SELECT state FROM experiments WHERE id = ?")
                .bind(&id)
                .fetch_one(&pool)
                .await
                .unwrap();
            pool.close().await;
            st
        });
        assert_eq!(state, "succeeded", "{}", db.display());
    }
    std::fs::remove_dir_all(alone).unwrap();
    std::fs::remove_dir_all(dir).unwrap();
}

/// Defect 16: a token sent in the query string never reaches the logs;
/// tokens can come from a file (not `ps`).
#[test]
fn tokens_stay_out_of_logs_and_can_come_from_a_file() {
    let dir = temp_dir("token");
    std::fs::write(dir.join("tokens"), "file-secret-token-16\n").unwrap();
    let child = Command::new(bin())
        .args(["serve", "--bind", "127.0.0.1:0", "--token-file"])
        .arg(dir.join("tokens"))
        .arg("--db")
        .arg(dir.join("t.db"))
        .env("RUST_LOG", "debug")
        .env_remove("ZWIDTH_TOKENS")
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(dir.join("err.log")).unwrap())
        .spawn()
        .unwrap();
    let mut s = Server {
        child,
        base: String::new(),
        _dir: dir.clone(),
    };
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(s.child.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    s.base = line.trim().rsplit(' ').next().unwrap().to_string();
    let _ = ureq::get(&format!("{}/healthz?access_token=query-secret", s.base)).call();
    let pause = format!("{}/v1/queue/pause", s.base);
    let (code, _, _) = call(authed::post(&pause).call());
    assert_eq!(code, 401);
    let (code, _, v) = call(
        authed::post(&pause)
            .set("authorization", "Bearer file-secret-token-16")
            .call(),
    );
    assert_eq!(code, 200, "{v}");
    // Both pause requests are logged once answered: wait for the lines.
    wait_for("the pause request in the log", 10, || {
        std::fs::read_to_string(dir.join("err.log"))
            .is_ok_and(|l| l.matches("queue/pause").count() >= 2)
    });
    let log = std::fs::read_to_string(dir.join("err.log")).unwrap();
    assert!(log.contains("healthz"), "the request was logged: {log}");
    assert!(!log.contains("query-secret"), "{log}");
    assert!(!log.contains("file-secret-token-16"), "{log}");
}

/// A small tmpfs, unmounted (and its directory removed) when dropped.
struct Tmpfs(std::path::PathBuf);

impl Tmpfs {
    /// Mount one (root only). `None` where this machine cannot; CI runs as
    /// root, so there the test fails rather than skips.
    fn mount(size: &str) -> Option<Tmpfs> {
        let dir = temp_dir("tmpfs");
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(&dir)
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            Some(Tmpfs(dir))
        } else {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must be able to mount a tmpfs (runs as root) for the disk-full test"
            );
            eprintln!("disk-full test not run: cannot mount a tmpfs here (not root)");
            let _ = std::fs::remove_dir_all(dir);
            None
        }
    }

    /// Fill it: a file grown until the disk says no.
    fn fill(&self) -> std::path::PathBuf {
        use std::io::Write;
        let p = self.0.join("filler");
        let mut f = std::fs::File::create(&p).unwrap();
        let chunk = vec![0u8; 16 * 1024];
        while f.write_all(&chunk).is_ok() {}
        let _ = f.flush();
        let _ = f.sync_all();
        p
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Defect 2: on a full disk a submission is acknowledged only when stored
/// (507 otherwise, and nothing half-written), a running experiment is held
/// rather than losing trials, and the store recovers without a restart
/// once space returns.
#[test]
fn a_full_disk_loses_no_acknowledged_submission_and_recovers() {
    let Some(fs) = Tmpfs::mount("6m") else { return };
    let data = fs.0.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let s = start_in(data.clone());
    let url = format!("{}/v1/experiments", s.base);
    // A running experiment of several seconds (time-domain, 10 kHz, 41
    // columns at standard accuracy: the claim must be seen before it ends,
    // also on a loaded machine, where four draft columns once ended first).
    let long = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":10000,"render_hz":1000}},"method":"time","criterion":"stability","b":[0,1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,25,26,27,28,29,30,31,32,33,34,35,36,37,38,39,40],"accuracy":"standard"}"#;
    let (code, _, v) = call(post_json(&url).send_string(long));
    assert_eq!(code, 202, "{v}");
    let running = v["id"].as_str().unwrap().to_string();
    // (120 s: under a loaded machine, with every test's server busy, the
    // claim has taken over 30 s.)
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let state = get(&format!("{url}/{running}"))["state"].clone();
        if state == "running" {
            break;
        }
        assert!(Instant::now() < deadline, "never seen running: {state}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let filler = fs.fill();
    // Submissions of ~20 kB each until the store refuses.
    let b: Vec<f64> = (0..1500).map(|i| i as f64 * 0.5).collect();
    let body = serde_json::json!({"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b": b}).to_string();
    let mut acked = Vec::new();
    let mut refused = 0;
    for _ in 0..400 {
        let (code, ct, v) = call(post_json(&url).send_string(&body));
        match code {
            202 => acked.push(v["id"].as_str().unwrap().to_string()),
            507 | 503 => {
                assert_eq!(ct, "application/problem+json", "{v}");
                refused += 1;
                if refused >= 3 {
                    break;
                }
            }
            _ => panic!("{code} {v}"),
        }
    }
    assert!(
        refused >= 3,
        "the disk never filled ({} stored)",
        acked.len()
    );
    // Every acknowledged submission is there; reads work on a full disk.
    for id in &acked {
        let (code, _, v) = call(ureq::get(&format!("{url}/{id}")).call());
        assert_eq!(code, 200, "{id}: {v}");
    }
    // The running experiment is held (its trials cannot be stored), not
    // silently "running" with trials lost.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let v = get(&format!("{url}/{running}"));
        if v["progress"]["held"].is_string() || v["state"] != "running" {
            break;
        }
        assert!(Instant::now() < deadline, "{v}");
        std::thread::sleep(Duration::from_millis(50));
    }
    // Space returns: writes work again without a restart.
    std::fs::remove_file(filler).unwrap();
    let small = SMALL;
    let deadline = Instant::now() + Duration::from_secs(10);
    let id = loop {
        let (code, _, v) = call(post_json(&url).send_string(small));
        if code == 202 {
            break v["id"].as_str().unwrap().to_string();
        }
        assert!(Instant::now() < deadline, "{code} {v}");
        std::thread::sleep(Duration::from_millis(200));
    };
    let done = wait_end(&s.base, &running, 120);
    assert_eq!(done["state"], "succeeded", "{done}");
    let stored = get(&format!("{url}/{running}/trials?limit=10000"));
    assert_eq!(
        stored.as_array().unwrap().len() as u64,
        done["result"]["trials"].as_u64().unwrap(),
        "every trial stored"
    );
    assert_eq!(get(&format!("{url}/{id}"))["id"], id.as_str());
    drop(s);
}

/// The server's peak resident memory so far (VmHWM, bytes).
fn peak_rss(s: &Server) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", s.child.id())).unwrap();
    let kb: u64 = status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap();
    kb * 1024
}

/// A sweep of `n` analytic impedance maps of SMALL's device over a
/// Butterworth cutoff (two columns each, milliseconds; one scene, so its
/// runs compare), succeeded: its id.
fn sweep(s: &Server, n: usize) -> String {
    let values: Vec<String> = (0..n)
        .map(|i| format!("{}", 10.0 + 2.0 * i as f64))
        .collect();
    let body = format!(
        r#"{{"kind":"sweep","map":{{"scene":{{"device":{{"coulomb":0,"quantization":0}},"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{{"kind":"butterworth","cutoff_hz":100}}}},"criterion":"impedance","b":[0,1]}},"parameter":{{"path":"estimator.cutoff_hz","values":[{}]}}}}"#,
        values.join(",")
    );
    let (code, v, _) = post(&format!("{}/v1/experiments", s.base), &body);
    assert_eq!(code, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    assert_eq!(wait_end(&s.base, &id, 120)["state"], "succeeded");
    id
}

/// Issue 30, defect 1: a comparison is bounded before it is built. Runs
/// holding more than `COMPARE_MAX_MAPS` maps are a 422 naming `runs` on the
/// page and the API (before: 50 sweeps of 200 maps gave a 407 MB page and
/// 3.65 GiB of RSS under 4 requests); a run page draws `PAGE_MAPS` (12)
/// maps a page, under 1 MB for the largest sweep (before: 8 MB); 4 parallel
/// requests of each raise the server's peak RSS by less than the budget in
/// docs/service.md (64 MiB).
#[test]
fn comparisons_and_run_pages_are_bounded_before_they_are_built() {
    use zwidth::http::compare::COMPARE_MAX_MAPS;
    let s = start();
    let big = sweep(&s, 200);
    let (a, b) = (sweep(&s, 20), sweep(&s, 20));
    // Within the budget: 40 maps.
    let ok = format!("{}/compare?runs={a},{b}", s.base);
    let (code, ct, page) = fetch(ureq::get(&ok).call());
    assert_eq!((code, ct.as_str()), (200, "text/html"));
    assert!(page.len() < 2_000_000, "{} bytes", page.len());
    // Past it: refused, naming runs and the budget, on the page and the API.
    let before = peak_rss(&s);
    let over = [big.as_str(), a.as_str(), b.as_str()].join(",");
    let threads: Vec<_> = (0..4)
        .map(|i| {
            let url = if i % 2 == 0 {
                format!("{}/compare?runs={over}", s.base)
            } else {
                format!("{}/v1/compare?runs={over}", s.base)
            };
            std::thread::spawn(move || fetch(ureq::get(&url).call()))
        })
        .collect();
    for (i, t) in threads.into_iter().enumerate() {
        let (code, _, body) = t.join().unwrap();
        assert_eq!(code, 422, "{body}");
        assert!(
            body.contains(&format!("at most {COMPARE_MAX_MAPS} maps")),
            "{body}"
        );
        if i % 2 == 1 {
            let v: serde_json::Value = serde_json::from_str(&body).unwrap();
            assert_eq!(v["field"], "runs", "{v}");
        }
    }
    // The largest sweep's page: 24 maps drawn, a pager to the rest.
    let pages: Vec<_> = (0..4)
        .map(|i| {
            let url = format!("{}/runs/{big}?page={}", s.base, i + 1);
            std::thread::spawn(move || fetch(ureq::get(&url).call()))
        })
        .collect();
    for p in pages {
        let (code, _, body) = p.join().unwrap();
        assert_eq!(code, 200);
        assert!(body.len() < 1_000_000, "{} bytes", body.len());
        assert!(body.contains("of 200 (12 a page)"), "a pager");
        assert_eq!(body.matches("<figure>").count(), 12);
    }
    let grown = peak_rss(&s).saturating_sub(before);
    assert!(grown < 64 << 20, "peak RSS grew {} MiB", grown >> 20);
    // The last page holds the remaining 8; one past it is a page naming `page`.
    let (code, _, last) = fetch(ureq::get(&format!("{}/runs/{big}?page=17", s.base)).call());
    assert_eq!((code, last.matches("<figure>").count()), (200, 8));
    let (code, ct, body) = fetch(ureq::get(&format!("{}/runs/{big}?page=18", s.base)).call());
    assert_eq!((code, ct.as_str()), (422, "text/html"));
    assert!(body.contains("page") && body.contains("1 to 17"), "{body}");
    // The compare page of 40 maps draws 12 a page too.
    let (_, _, second) = fetch(ureq::get(&format!("{ok}&page=2")).call());
    assert_eq!(
        second.matches("<figure>").count(),
        12,
        "12 maps (the overlay is a figure of its own class)"
    );
}

/// Issue 30, defect 10: the dashboard's errors are pages with the problem's
/// title, detail and status (before: raw JSON in the browser); every
/// response says `nosniff`; an SVG carries a policy that runs no script.
#[test]
fn dashboard_errors_are_pages_and_every_response_is_marked() {
    let s = start();
    let r = ureq::get(&format!("{}/runs/nope", s.base)).call();
    let Err(ureq::Error::Status(404, r)) = r else {
        panic!("a 404")
    };
    assert_eq!(r.content_type(), "text/html");
    assert_eq!(r.header("x-content-type-options"), Some("nosniff"));
    let body = r.into_string().unwrap();
    assert!(
        body.contains("<h1>Not found</h1>") && body.contains("no experiment nope"),
        "{body}"
    );
    // Two runs on different scenes: the compare page says why, as a page.
    let (code, v, _) = post(&format!("{}/v1/experiments", s.base), SMALL);
    assert_eq!(code, 202, "{v}");
    let one = v["id"].as_str().unwrap().to_string();
    let (code, v, _) = post(
        &format!("{}/v1/experiments", s.base),
        &SMALL.replace("\"coulomb\":0", "\"coulomb\":0,\"mass\":0.5"),
    );
    assert_eq!(code, 202, "{v}");
    let two = v["id"].as_str().unwrap().to_string();
    for id in [&one, &two] {
        assert_eq!(wait_end(&s.base, id, 60)["state"], "succeeded");
    }
    let (code, ct, body) = fetch(ureq::get(&format!("{}/compare?runs={one},{two}", s.base)).call());
    assert_eq!((code, ct.as_str()), (422, "text/html"), "{body}");
    assert!(
        body.contains("<!DOCTYPE html>") && body.contains("scene"),
        "{body}"
    );
    // The JSON API keeps problem+json.
    let (code, ct, _) = fetch(ureq::get(&format!("{}/v1/experiments/nope", s.base)).call());
    assert_eq!((code, ct.as_str()), (404, "application/problem+json"));
    for path in [
        "/",
        "/v1/queue",
        "/healthz",
        "/v1/nothing",
        "/assets/style.css",
    ] {
        let r = match ureq::get(&format!("{}{path}", s.base)).call() {
            Ok(r) | Err(ureq::Error::Status(_, r)) => r,
            Err(e) => panic!("{e}"),
        };
        assert_eq!(
            r.header("x-content-type-options"),
            Some("nosniff"),
            "{path}"
        );
    }
    for path in [
        format!("/v1/experiments/{one}/plot.svg"),
        format!("/v1/compare?runs={one}&format=svg"),
    ] {
        let r = ureq::get(&format!("{}{path}", s.base)).call().unwrap();
        assert_eq!(r.content_type(), "image/svg+xml");
        let csp = r.header("content-security-policy").unwrap_or("");
        assert!(
            csp.contains("default-src 'none'") && !csp.contains("script"),
            "{path}: {csp}"
        );
    }
}

/// Issue 30, defect 4: a client cannot hold connections it does not use.
/// Idle connections, a partial request line and a header trickled every
/// 2 s are all closed by the header-read timeout (10 s; before: all open
/// after 75 s), and one address holds at most its cap (8 here) at once.
#[test]
fn slow_and_idle_clients_are_cut_off_and_capped() {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use zwidth::http::accept::HEADER_READ_TIMEOUT;
    let dir = temp_dir("slow");
    let s = start_with(dir, &["--max-connections-per-client", "8"]);
    let addr = s.base.trim_start_matches("http://").to_string();
    let open = || {
        let c = TcpStream::connect(&addr).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        c
    };
    let mut idle: Vec<TcpStream> = (0..3).map(|_| open()).collect();
    let mut partial = open();
    partial.write_all(b"GET /v1/queue HT").unwrap();
    let mut trickle = open();
    trickle.write_all(b"GET /v1/queue HTTP/1.1\r\n").unwrap();
    // The cap: 5 held, 3 more fill it, the 9th is answered 503 and closed.
    let more: Vec<TcpStream> = (0..3).map(|_| open()).collect();
    let mut ninth = open();
    let mut text = String::new();
    ninth.read_to_string(&mut text).unwrap();
    assert!(
        text.starts_with("HTTP/1.1 503") && text.contains("\"status\":503"),
        "{text}"
    );
    drop(more);
    let t0 = Instant::now();
    let closed = |c: &mut TcpStream| {
        let mut buf = [0u8; 512];
        // The server closes (0 bytes) or answers 408 then closes.
        loop {
            match c.read(&mut buf) {
                Ok(0) | Err(_) => return,
                Ok(_) => continue,
            }
        }
    };
    // The trickler sends a header line every 2 s until it is cut off.
    let trickler = std::thread::spawn(move || {
        for i in 0..40 {
            if trickle
                .write_all(format!("x-slow-{i}: 1\r\n").as_bytes())
                .is_err()
            {
                return Instant::now();
            }
            std::thread::sleep(Duration::from_secs(2));
        }
        panic!("the trickling client was never cut off");
    });
    for c in idle.iter_mut() {
        closed(c);
    }
    closed(&mut partial);
    let waited = t0.elapsed();
    assert!(
        waited < HEADER_READ_TIMEOUT + Duration::from_secs(5),
        "{waited:?}"
    );
    let cut = trickler.join().unwrap().duration_since(t0);
    assert!(
        cut < HEADER_READ_TIMEOUT + Duration::from_secs(8),
        "{cut:?}"
    );
    // The server serves as before.
    assert_eq!(get(&format!("{}/healthz", s.base))["status"], "ok");
}

/// Issue 45 item 11: a key written twice was taken silently, the last one
/// winning (`{"kind":"map","kind":"compare"}` → 202, run as a compare). Now
/// refused everywhere a document is read, naming the key: the API (422),
/// the CLI's files (exit 2), and nothing is stored.
#[test]
fn a_key_written_twice_is_refused_naming_it() {
    let s = start();
    let url = format!("{}/v1/experiments", s.base);
    let (code, ct, v) = call(post_json(&url).send_string(r#"{"kind":"map","kind":"compare"}"#));
    assert_problem(code, &ct, &v, 422, Some("kind"));
    assert!(v["detail"].as_str().unwrap().contains("twice"), "{v}");
    let nested = SMALL.replace(r#""coulomb":0,"#, r#""coulomb":0,"coulomb":1,"#);
    let (code, ct, v) = call(post_json(&url).send_string(&nested));
    assert_problem(code, &ct, &v, 422, Some("scene.device.coulomb"));
    // Nothing was stored.
    assert_eq!(
        get(&url)["experiments"].as_array().map(Vec::len),
        Some(0),
        "{}",
        get(&url)
    );
    // A rig registration too.
    let (code, ct, v) =
        call(post_json(&format!("{}/v1/rigs", s.base)).send_string(r#"{"id":"a","id":"b"}"#));
    assert_problem(code, &ct, &v, 422, Some("id"));
    // The CLI: a scene file with a key written twice, exit 2 naming it.
    let dir = temp_dir("dup");
    let scene = dir.join("scene.json");
    std::fs::write(&scene, r#"{"device":{"mass":0.5,"mass":5}}"#).unwrap();
    let out = Command::new(bin())
        .args(["map", "--accuracy", "draft", "--scene"])
        .arg(&scene)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("device.mass") && err.contains("twice"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
