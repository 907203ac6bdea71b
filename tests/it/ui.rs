//! The dashboard's pages (issue 15) on a seeded database, through the real
//! router in this process: HTML with the expected content, SVG marks that
//! count the stored trials, hostile strings escaped, the polling contract
//! (204 while nothing changed), bad queries as problems naming the field.
//! SQLite always; PostgreSQL too when configured (`crate::common::pg`).

use axum::body::Body;
use axum::http::{Request, StatusCode};
use tower::ServiceExt;
use zwidth::http::ui::bench::{seed, Seeded};
use zwidth::http::{router, AppState};
use zwidth::store::{Location, Store};

struct Dir(std::path::PathBuf);
impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

const TOKEN: &str = "ui-test-token-0123456789";

/// Fresh stores (SQLite, and PostgreSQL when configured), each seeded with
/// 40 runs and 7 000 trials, 3 500 of them in one run (more than the
/// page's tooltip budget, `run::TOOLTIP_BUDGET` = 3 000).
async fn seeded(name: &str) -> Vec<(axum::Router, Store, Seeded, Option<Dir>)> {
    let d = std::env::temp_dir().join(format!("zwidth-ui-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let mut stores = vec![(
        Store::connect(&Location::Sqlite(d.join("z.db")))
            .await
            .unwrap(),
        Some(Dir(d)),
    )];
    if let Some(url) = crate::common::pg::fresh_database(name).await {
        stores.push((
            Store::connect(&Location::Postgres(url)).await.unwrap(),
            None,
        ));
    }
    let mut out = Vec::new();
    for (store, dir) in stores {
        let s = seed(&store, 40, 7000, 3500).await.unwrap();
        let mut st = AppState::reader(store.clone()).unwrap();
        st.tokens = std::sync::Arc::new(vec![TOKEN.to_string()]);
        let app = router(st, std::time::Duration::from_secs(30));
        out.push((app, store, s, dir));
    }
    out
}

async fn get(app: &axum::Router, path: &str) -> (StatusCode, String, String) {
    let r = app
        .clone()
        .oneshot(Request::get(path).body(Body::empty()).unwrap())
        .await
        .unwrap();
    let status = r.status();
    let kind = r
        .headers()
        .get("content-type")
        .map(|v| v.to_str().unwrap().to_string())
        .unwrap_or_default();
    let body = axum::body::to_bytes(r.into_body(), usize::MAX)
        .await
        .unwrap();
    (status, kind, String::from_utf8(body.to_vec()).unwrap())
}

/// The text between `<h2>`'s `(` and `)` after `heading`: a section's count.
fn count_after(html: &str, heading: &str) -> i64 {
    let at = html
        .find(heading)
        .unwrap_or_else(|| panic!("no {heading:?}"));
    let rest = &html[at..];
    let open = rest.find('(').unwrap();
    let close = rest[open..].find(')').unwrap() + open;
    rest[open + 1..close].parse().unwrap()
}

#[tokio::test]
async fn every_page_answers_html_with_the_seeded_runs() {
    for (app, store, s, _dir) in seeded("pages").await {
        // The queue's counts against the store's own count by state.
        let (by_state, _) = store.counts().await.unwrap();
        let n = |st: &str| {
            by_state
                .iter()
                .find(|(s, _)| s == st)
                .map_or(0, |(_, n)| *n)
        };
        let (code, kind, html) = get(&app, "/").await;
        assert_eq!(code, StatusCode::OK);
        assert!(kind.starts_with("text/html"), "{kind}");
        assert_eq!(count_after(&html, "Running"), n("running"));
        assert_eq!(count_after(&html, "Waiting"), n("queued") + n("scheduled"));
        // Seeded failures all ended in the last day.
        assert_eq!(count_after(&html, "Failed in the last 24 h"), n("failed"));
        assert!(
            html.contains("seeded failure"),
            "the failure's message is shown"
        );
        assert!(html.contains("/assets/htmx-2.0.11.min.js"));
        // Every asset the pages name is served from the binary.
        for a in ["htmx-2.0.11.min.js", "app.js", "style.css"] {
            let (code, _, body) = get(&app, &format!("/assets/{a}")).await;
            assert_eq!(code, StatusCode::OK, "{a}");
            assert!(body.len() > 500, "{a}");
        }
        assert_eq!(get(&app, "/assets/nope.js").await.0, StatusCode::NOT_FOUND);

        // The run list: 40 runs, 50 a page: all on page 1, newest first.
        let (code, _, html) = get(&app, "/runs").await;
        assert_eq!(code, StatusCode::OK);
        assert!(html.contains("40 runs; page 1 of 1."), "{html}");
        assert_eq!(html.matches("href=\"/runs/").count(), 40);
        let (_, _, html) = get(&app, "/runs?kind=tune").await;
        assert!(html.contains("1 runs; page 1 of 1."));
        assert!(html.contains(zwidth::report::short_id(&s.tune)));
        let (_, _, html) = get(&app, "/runs?state=failed&rig=sim").await;
        assert!(html.contains(&format!("{} runs;", n("failed"))), "{html}");
        // Scene text: every map spec names its Butterworth filter; the tune's too.
        let (_, _, html) = get(&app, "/runs?scene=butterworth").await;
        assert!(html.contains("40 runs;"));
        let (_, _, html) = get(&app, "/runs?scene=levant").await;
        assert!(html.contains("0 runs;"));

        // A compare of the seeded pair, and the picker without runs.
        let (code, _, html) =
            get(&app, &format!("/compare?runs={},{}", s.pair[0], s.pair[1])).await;
        assert_eq!(code, StatusCode::OK, "{html}");
        assert!(html.contains("Compare 2 runs"));
        assert!(html.contains("The specs are the same."));
        let (code, _, html) = get(&app, "/compare").await;
        assert_eq!(code, StatusCode::OK);
        assert!(html.contains("Pick runs on the same scene"));

        // The tune: one mark per stored evaluation, plus the best's ring.
        let evals = store.evaluations(&s.tune).await.unwrap();
        let (code, _, html) = get(&app, &format!("/runs/{}", s.tune)).await;
        assert_eq!(code, StatusCode::OK);
        assert!(
            html.contains("against cutoff_hz"),
            "one parameter: the landscape"
        );
        assert_eq!(html.matches("class=\"pt\"").count(), evals.len() + 1);
    }
}

#[tokio::test]
async fn map_marks_count_the_stored_trials_and_a_big_run_stays_small() {
    for (app, store, s, _dir) in seeded("marks").await {
        // A typical run: one element with a tooltip per stored trial.
        let n = store.trial_count(&s.typical).await.unwrap() as usize;
        assert!(n > 0);
        let (code, _, html) = get(&app, &format!("/runs/{}", s.typical)).await;
        assert_eq!(code, StatusCode::OK);
        assert_eq!(html.matches("class=\"pt ").count(), n);
        assert_eq!(html.matches("<title>B = ").count(), n);
        // The biggest: drawn compactly; its paths' counts add up to the trials.
        let n = store.trial_count(&s.big).await.unwrap() as usize;
        assert_eq!(n, 3500);
        let (_, _, html) = get(&app, &format!("/runs/{}", s.big)).await;
        let total: usize = html
            .match_indices("data-n=\"")
            .map(|(i, m)| {
                let rest = &html[i + m.len()..];
                rest[..rest.find('"').unwrap()].parse::<usize>().unwrap()
            })
            .sum();
        assert_eq!(total, n);
        assert_eq!(html.matches("class=\"pt ").count(), 0);
    }
}

/// The run page reads a run's points joined per scope in the database
/// (`Store::map_points`): the same points, in the same order, as the
/// trials read one row each (`Store::trials`); a damaged stored point is
/// left out as `trials` leaves it out, not the whole map.
#[tokio::test]
async fn map_points_are_the_stored_trials_in_order_and_a_damaged_one_is_left_out() {
    for (app, store, s, dir) in seeded("points").await {
        for id in [&s.typical, &s.big] {
            let joined: Vec<serde_json::Value> = store
                .map_points(id)
                .await
                .unwrap()
                .into_iter()
                .flat_map(|(scope, pts)| {
                    pts.into_iter().map(move |p| serde_json::json!([scope, p]))
                })
                .collect();
            let rows: Vec<serde_json::Value> = store
                .trials(id)
                .await
                .unwrap()
                .into_iter()
                .map(|t| serde_json::json!([t.scope, t.point]))
                .collect();
            assert!(!rows.is_empty());
            assert_eq!(joined, rows);
        }
        // SQLite: damage one stored point of the typical run by hand.
        let Some(Dir(d)) = &dir else { continue };
        let n = store.trial_count(&s.typical).await.unwrap() as usize;
        let pool = sqlx::SqlitePool::connect(&format!("sqlite://{}", d.join("z.db").display()))
            .await
            .unwrap();
        sqlx::query(
            "UPDATE trials SET point = '{' WHERE rowid = \
             (SELECT rowid FROM trials WHERE experiment_id = $1 LIMIT 1)",
        )
        .bind(&s.typical)
        .execute(&pool)
        .await
        .unwrap();
        pool.close().await;
        assert_eq!(store.trials(&s.typical).await.unwrap().len(), n - 1);
        let points: usize = store
            .map_points(&s.typical)
            .await
            .unwrap()
            .iter()
            .map(|(_, p)| p.len())
            .sum();
        assert_eq!(points, n - 1);
        let (code, _, html) = get(&app, &format!("/runs/{}", s.typical)).await;
        assert_eq!(code, StatusCode::OK);
        assert_eq!(html.matches("class=\"pt ").count(), n - 1);
    }
}

#[tokio::test]
async fn a_twenty_thousand_trial_run_page_is_under_a_megabyte() {
    let d = std::env::temp_dir().join(format!("zwidth-ui-big-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let _dir = Dir(d.clone());
    let store = Store::connect(&Location::Sqlite(d.join("z.db")))
        .await
        .unwrap();
    let s = seed(&store, 3, 20_000, 20_000).await.unwrap();
    assert_eq!(store.trial_count(&s.big).await.unwrap(), 20_000);
    let app = router(
        AppState::reader(store).unwrap(),
        std::time::Duration::from_secs(30),
    );
    let (code, _, html) = get(&app, &format!("/runs/{}", s.big)).await;
    assert_eq!(code, StatusCode::OK);
    // The issue's target: a run page with 20 000 trials stays under 1 MB.
    assert!(html.len() < 1_000_000, "{} bytes", html.len());
    assert!(html.contains("20000 trials"));
}

#[tokio::test]
async fn the_live_part_answers_204_while_nothing_changed() {
    for (app, store, s, _dir) in seeded("live").await {
        let (_, _, html) = get(&app, &format!("/runs/{}", s.big)).await;
        // A finished run's part does not poll; its token is still given.
        let at = html.find("data-token=\"").unwrap() + "data-token=\"".len();
        let token = &html[at..at + html[at..].find('"').unwrap()];
        let enc: String = serde_urlencoded::to_string([("since", token)]).unwrap();
        let (code, _, body) = get(&app, &format!("/ui/runs/{}/live?{enc}", s.big)).await;
        assert_eq!(code, StatusCode::NO_CONTENT);
        assert!(body.is_empty());
        let (code, _, body) = get(&app, &format!("/ui/runs/{}/live?since=old", s.big)).await;
        assert_eq!(code, StatusCode::OK);
        assert!(body.starts_with("<section id=\"live\""), "{}", &body[..80]);
        // The queue polls; its token holds until the queue changes.
        let (_, _, html) = get(&app, "/").await;
        assert!(html.contains("hx-trigger=\"every 2s, refresh\""));
        let at = html.find("data-token=\"").unwrap() + "data-token=\"".len();
        let token = html[at..at + html[at..].find('"').unwrap()].to_string();
        let enc = serde_urlencoded::to_string([("since", &token)]).unwrap();
        assert_eq!(
            get(&app, &format!("/ui/queue/live?{enc}")).await.0,
            StatusCode::NO_CONTENT
        );
        // A run joins the queue in the store (another process's submit):
        // the same token now answers the part, showing it.
        let mut row = store.get(&s.typical).await.unwrap().unwrap();
        row.id = "joined-the-queue".into();
        row.state = zwidth::store::ExperimentState::Queued;
        (row.started_ms, row.finished_ms, row.result) = (None, None, None);
        store.import_run(&row, &[], &[]).await.unwrap();
        let (code, _, body) = get(&app, &format!("/ui/queue/live?{enc}")).await;
        assert_eq!(code, StatusCode::OK);
        assert!(body.contains("/runs/joined-the-queue"), "the new run shown");
    }
}

#[tokio::test]
async fn hostile_strings_come_out_escaped() {
    for (app, store, s, _dir) in seeded("hostile").await {
        let evil = "<script>alert(1)</script>\"'&";
        // Echoed filter values (attribute and text).
        let q = serde_urlencoded::to_string([("scene", evil)]).unwrap();
        let (code, _, html) = get(&app, &format!("/runs?{q}")).await;
        assert_eq!(code, StatusCode::OK);
        assert!(!html.contains("<script>alert(1)"), "unescaped");
        assert!(
            html.contains("&lt;script&gt;alert(1)&lt;/script&gt;&quot;'&amp;"),
            "escaped"
        );
        // A rig registered with a hostile description, and a failure whose
        // message carries markup.
        let r = app
            .clone()
            .oneshot(
                Request::post("/v1/rigs")
                    .header("authorization", format!("Bearer {TOKEN}"))
                    .header("content-type", "application/json")
                    .body(Body::from(
                        serde_json::json!({"id": "evil", "description": "<img src=x onerror=alert(2)>"})
                            .to_string(),
                    ))
                    .unwrap(),
            )
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::CREATED);
        // A NUL in a description: PostgreSQL's text cannot hold it (a 500
        // there before); refused on both databases naming the field.
        let r = app
            .clone()
            .oneshot(
                Request::post("/v1/rigs")
                    .header("authorization", format!("Bearer {TOKEN}"))
                    .header("content-type", "application/json")
                    .body(Body::from(r#"{"id":"nul","description":"a\u0000b"}"#))
                    .unwrap(),
            )
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::UNPROCESSABLE_ENTITY);
        let body = axum::body::to_bytes(r.into_body(), 1 << 16).await.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["field"], "description", "{v}");
        let mut row = store.get(&s.typical).await.unwrap().unwrap();
        row.id = "hostile-run".into();
        row.state = zwidth::store::ExperimentState::Failed;
        row.finished_ms = Some(zwidth::clock::now_ms());
        row.error = Some("<b onmouseover=alert(3)>boom</b>".into());
        store.import_run(&row, &[], &[]).await.unwrap();
        let (_, _, html) = get(&app, "/").await;
        assert!(!html.contains("<img src=x"));
        assert!(html.contains("&lt;img src=x onerror=alert(2)&gt;"));
        assert!(!html.contains("<b onmouseover"));
        assert!(html.contains("&lt;b onmouseover=alert(3)&gt;boom&lt;/b&gt;"));
        let (_, _, html) = get(&app, "/runs/hostile-run").await;
        assert!(html.contains("&lt;b onmouseover=alert(3)&gt;"));
        // Pages forbid inline script.
        let r = app
            .clone()
            .oneshot(Request::get("/").body(Body::empty()).unwrap())
            .await
            .unwrap();
        let csp = r.headers()["content-security-policy"].to_str().unwrap();
        assert!(
            csp.contains("script-src 'self'") && !csp.contains("unsafe-eval"),
            "{csp}"
        );
    }
}

#[tokio::test]
async fn compare_shows_differences_only_and_one_colour_scale() {
    for (app, store, s, _dir) in seeded("compare").await {
        // A second run on the same scene with another cutoff, and twice
        // the first's fidelity errors.
        let mut row = store.get(&s.pair[0]).await.unwrap().unwrap();
        let trials = store.trials(&s.pair[0]).await.unwrap();
        let mut result: serde_json::Value =
            serde_json::from_str(row.result.as_deref().unwrap()).unwrap();
        let passive_fid = |r: &serde_json::Value| -> Vec<f64> {
            r["points"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|p| p["passive"].as_bool() == Some(true))
                .filter_map(|p| p["fidelity"].as_f64())
                .collect()
        };
        let first = passive_fid(&result);
        assert!(!first.is_empty(), "the template has fidelity errors");
        for p in result["points"].as_array_mut().unwrap() {
            if let Some(f) = p["fidelity"].as_f64() {
                p["fidelity"] = serde_json::json!(2.0 * f);
            }
        }
        row.id = "other-cutoff".into();
        row.spec = row
            .spec
            .replace("\"cutoff_hz\":200.0", "\"cutoff_hz\":300.0");
        assert!(row.spec.contains("300.0"), "{}", row.spec);
        row.result = Some(result.to_string());
        store.import_run(&row, &trials, &[]).await.unwrap();
        let path = format!("/compare?runs={},other-cutoff", s.pair[0]);
        let (code, _, html) = get(&app, &path).await;
        assert_eq!(code, StatusCode::OK, "{html}");
        let diff = &html[html.find("class=\"spec-diff\"").unwrap()..];
        assert!(diff.contains("scene.estimator.cutoff_hz"));
        assert!(
            !diff.contains("scene.loop.sample_hz"),
            "same values are hidden"
        );
        let (_, _, all) = get(&app, &format!("{path}&all=1")).await;
        assert!(
            all.contains("scene.loop.sample_hz"),
            "every field with all=1"
        );
        // One colour scale for both panels: each colour bar runs from the
        // smallest error of either map (the first's) to the largest (the
        // second's, twice the first's largest), labelled `{:.1}`.
        let lo = first.iter().cloned().fold(f64::MAX, f64::min);
        let hi = 2.0 * first.iter().cloned().fold(f64::MIN, f64::max);
        // (plotters writes a text's content on a line of its own)
        let flat = html.replace('\n', "");
        for label in [format!(">{lo:.1}</text>"), format!(">{hi:.1}</text>")] {
            assert_eq!(
                flat.matches(&label).count(),
                2,
                "{label} on both colour bars"
            );
        }
        // Intervals: two more runs on that scene. Their K-width intervals
        // overlap: the orders table says so and no K-width is marked best;
        // made disjoint, the wider one is.
        for (n, (a, b)) in [
            ([3.8e5, 4.2e5], [4.1e5, 4.6e5]),
            ([3.8e5, 4.0e5], [4.1e5, 4.6e5]),
        ]
        .into_iter()
        .enumerate()
        {
            let ids = [format!("iv-a{n}"), format!("iv-b{n}")];
            for (id, k, iv) in [(&ids[0], 4.0e5, a), (&ids[1], 4.5e5, b)] {
                let mut r = row.clone();
                r.id = id.clone();
                let mut res = result.clone();
                res["k_width"] = serde_json::json!(k);
                res["k_width_interval"] = serde_json::json!(iv);
                r.result = Some(res.to_string());
                store.import_run(&r, &trials, &[]).await.unwrap();
            }
            let (code, _, html) = get(&app, &format!("/compare?runs={}", ids.join(","))).await;
            assert_eq!(code, StatusCode::OK, "{html}");
            assert!(html.contains("Which is wider"), "{html}");
            // The K-widths ranked: the second run first, then ≈ (overlap)
            // or > (resolved) before the first.
            let chain = html
                .split("<strong>K-width: </strong>")
                .nth(1)
                .and_then(|t| t.split("</p>").next())
                .unwrap_or_default();
            assert_eq!(chain.contains('≈'), a[1] >= b[0], "{chain}");
            assert_eq!(chain.contains("&gt;"), a[1] < b[0], "{chain}");
            let overlap = a[1] >= b[0];
            assert_eq!(
                html.contains("not resolved (the intervals overlap)"),
                overlap
            );
            assert_eq!(
                html.contains(r#">450000<span class="sr"> (best)</span>"#),
                !overlap,
                "{html}"
            );
            assert!(html.contains("[410000, 460000]"), "{html}");
        }
    }
}

#[tokio::test]
async fn bad_queries_are_problems_naming_the_field() {
    for (app, _store, _s, _dir) in seeded("bad").await {
        for (path, code, field) in [
            ("/runs?kind=bogus", 422, "kind"),
            ("/runs?state=done", 422, "state"),
            ("/runs?page=0", 422, "page"),
            ("/runs?colour=red", 422, "colour"),
            ("/compare?x=1", 422, "x"),
            ("/compare?runs=,,,", 422, "runs"),
            ("/compare?runs=no-such-run", 404, "runs"),
            ("/runs?page=2", 422, "page"),
            // A NUL byte: PostgreSQL's text cannot hold one (a 500 before).
            ("/runs?scene=%00", 422, "query"),
            ("/runs/%00", 404, "path"),
            ("/ui/runs/%00/live", 404, "path"),
            ("/compare?runs=%00", 422, "query"),
            ("/v1/experiments/%00", 404, "path"),
            ("/runs/no-such-run", 404, ""),
            ("/ui/runs/no-such-run/live", 404, ""),
        ] {
            let (c, kind, body) = get(&app, path).await;
            assert_eq!(c.as_u16(), code, "{path}: {body}");
            // The JSON API, and a target refused before routing (a NUL),
            // answer problem+json; the dashboard's pages answer a page
            // with the problem's title, detail and field (issue 30).
            if path.starts_with("/v1/") || path.contains("%00") {
                assert!(
                    kind.starts_with("application/problem+json"),
                    "{path}: {kind}"
                );
                if !field.is_empty() {
                    let v: serde_json::Value = serde_json::from_str(&body).unwrap();
                    assert_eq!(v["field"], field, "{path}: {v}");
                }
            } else {
                assert!(kind.starts_with("text/html"), "{path}: {kind}");
                if !field.is_empty() {
                    assert!(
                        body.contains(&format!("Field: <code>{field}</code>")),
                        "{path}: {body}"
                    );
                }
            }
        }
    }
}

/// A compare's refinement rounds store row i's later maps as scope
/// r·n + i (`compare::scopes`): the run page draws one panel a row, with
/// the row's latest map's trials (here 2 rows: scopes 0, 1, then round 1's
/// 2 and 3, with 3 and 2 trials, against 5 and 4 in the first maps).
#[tokio::test]
async fn a_refined_compare_draws_each_row_once_with_its_latest_map() {
    use zwidth::store::{Lease, NewExperiment};
    use zwidth::zwidth::point::{Point, StoredTrial};
    let d = std::env::temp_dir().join(format!("zwidth-ui-refined-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let store = Store::connect(&Location::Sqlite(d.join("z.db")))
        .await
        .unwrap();
    store
        .insert(NewExperiment::queued("c1", "compare", r#"{"kind":"compare","accuracy":"draft","estimators":[{"kind":"fdm"},{"kind":"fdm"}],"resolve_rounds":1}"#, "sim"))
        .await
        .unwrap();
    let row = store.claim("sim", "w1", 60_000).await.unwrap().unwrap();
    let run = Lease::of(row.id, row.attempt);
    let trials: Vec<StoredTrial> = [(0, 5), (1, 4), (2, 3), (3, 2)]
        .into_iter()
        .flat_map(|(scope, n)| {
            (0..n).map(move |i| StoredTrial {
                scope,
                column: 0,
                index: i,
                point: Point {
                    k: 1000.0 * (i + 1) as f64,
                    b: 0.0,
                    passive: Some(i % 2 == 0),
                    ..Point::default()
                },
            })
        })
        .collect();
    store
        .add_trials(&run, &trials, &[], (0, 0.0))
        .await
        .unwrap();
    let mut st = AppState::reader(store.clone()).unwrap();
    st.tokens = std::sync::Arc::new(vec![TOKEN.to_string()]);
    let app = router(st, std::time::Duration::from_secs(30));
    let (code, _, html) = get(&app, "/runs/c1").await;
    assert_eq!(code, StatusCode::OK, "{html}");
    // 3 + 2 trials drawn (round 1's), not 5 + 4 + 3 + 2; no third panel.
    assert_eq!(html.matches("class=\"pt ").count(), 5, "{html}");
    assert!(!html.contains("map 2"), "{html}");
    let _ = std::fs::remove_dir_all(&d);
}
