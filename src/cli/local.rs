//! Commands that run the engines locally: trial, impedance, map, tune,
//! compare, bench, estimate, accuracy, lipschitz, gains.

use std::io::{BufRead, BufWriter, Write};

use crate::accuracy::{self, AccuracyConfig};
use crate::estimators::{EstimatorKind, EstimatorSpec, Sampling, VelocityEstimator};
use crate::lipschitz;
use crate::plot::{loglog_svg, FidelityScale, Series};
use crate::zwidth::compare;
use crate::zwidth::hit::{wall_hit, HitKnobs, NoTrace, TraceRow};
use crate::zwidth::prior::Prior;
use crate::zwidth::scene::validate_wall;
use crate::zwidth::search::{map_observed, Evaluator, Observer};
use crate::zwidth::settings::{
    Accuracy, AccuracyKnobs, Criterion, MapSpec, Method, Preset, SearchKind,
};
use crate::zwidth::tradeoff;

use super::common::*;
use super::{BenchCommand, CliError, Command};

pub(super) fn run(
    command: Command,
    stdin: impl BufRead,
    stdout: &mut impl Write,
) -> Result<(), CliError> {
    match command {
        Command::Trial {
            scene,
            k,
            b,
            json,
            trace,
        } => {
            let sc = read_scene(&scene)?.validate()?;
            validate_wall(k, b)?;
            let knobs = HitKnobs {
                settle_s: sc.spec.hit.settle_s,
                measure_s: sc.spec.hit.measure_s,
            };
            let outcome = if let Some(path) = &trace {
                let worst = (sc.spec.hit.settle_s * 11.0 + sc.spec.hit.measure_s + 60.0)
                    * sc.spec.control.sample_hz;
                if worst > 1e7 {
                    return Err(CliError::Input(format!(
                        "--trace: this trial may run to {worst:.0} samples; traces are limited to 10 000 000 rows (shorten hit.settle_s/measure_s or lower loop.sample_hz)"
                    )));
                }
                let mut rows: Vec<TraceRow> = Vec::new();
                let o = wall_hit(&sc, k, b, knobs, &mut rows);
                let mut csv = String::from(
                    "t_s,x_true_m,y_measured_m,v_est_m_per_s,v_true_m_per_s,force_n\n",
                );
                for r in rows {
                    csv.push_str(&format!(
                        "{},{},{},{},{},{}\n",
                        r.t, r.x, r.y, r.v_est, r.v, r.force
                    ));
                }
                write_file(path, &csv)?;
                o
            } else {
                wall_hit(&sc, k, b, knobs, &mut NoTrace)
            };
            if json {
                write_json(stdout, &outcome)
            } else {
                let rms = outcome
                    .rms
                    .map(|r| format!("{r:.3e} m"))
                    .unwrap_or("- (diverged)".into());
                writeln!(
                    stdout,
                    "{} (RMS {rms} about {:.6e} m, threshold {:.3e} m; {} samples)",
                    if outcome.stable { "stable" } else { "unstable" },
                    outcome.mean_position,
                    sc.spec.hit.threshold,
                    outcome.samples
                )
                .map_err(io)
            }
        }
        Command::Impedance {
            scene,
            k,
            b,
            method,
            accuracy,
            json,
        } => {
            let sc = read_scene(&scene)?.validate()?;
            validate_wall(k, b)?;
            let method: Method = parse_choice("method", &method)?;
            let acc = Accuracy::Preset(parse_choice("accuracy", &accuracy)?);
            let res = acc.resolve(&sc)?;
            let ev = Evaluator::new(sc, method, Criterion::Impedance, res)?;
            let curve = ev.impedance(k, b).ok_or_else(|| {
                CliError::Input("--method must be auto, analytic or frequency".into())
            })?;
            if json {
                #[derive(serde::Serialize)]
                struct Out<'a> {
                    model: String,
                    #[serde(flatten)]
                    curve: &'a crate::zwidth::analytic::ImpedanceCurve,
                }
                write_json(
                    stdout,
                    &Out {
                        model: ev.model_description(),
                        curve: &curve,
                    },
                )
            } else {
                let mut s = format!(
                    "model: {}
{:>10} {:>14} {:>10}
",
                    ev.model_description(),
                    "f (Hz)",
                    "|Z| (N·s/m)",
                    "phase (°)"
                );
                for i in 0..curve.freq_hz.len() {
                    s.push_str(&format!(
                        "{:>10.2} {:>14.4} {:>10.3}
",
                        curve.freq_hz[i], curve.magnitude[i], curve.phase_deg[i]
                    ));
                }
                s.push_str(&format!(
                    "{}; fidelity error {:.3} N·s/m
",
                    if curve.passive {
                        "passive (phase within ±90° over the band)"
                    } else {
                        "NOT passive"
                    },
                    curve.fidelity
                ));
                write!(stdout, "{s}").map_err(io)
            }
        }
        Command::Map {
            scene,
            method,
            criterion,
            search,
            b,
            k_rel_tol,
            accuracy,
            json,
            svg,
            prior_scene,
            prior_map,
        } => {
            let prior = match (prior_scene, prior_map) {
                (Some(path), _) => Some(Prior::Scene(Box::new(read_scene_of(
                    "--prior-scene",
                    &path,
                )?))),
                (None, Some(path)) => Some(Prior::Boundary(read_boundary(&path)?)),
                (None, None) => None,
            };
            let spec = MapSpec {
                scene: read_scene(&scene)?,
                method: parse_choice("method", &method)?,
                criterion: parse_choice("criterion", &criterion)?,
                search: parse_choice::<SearchKind>("search", &search)?,
                accuracy: Accuracy::Knobs(AccuracyKnobs {
                    preset: parse_choice::<Preset>("accuracy", &accuracy)?,
                    k_rel_tol,
                    ..Default::default()
                }),
                b,
                b_max: 1000.0,
                k_max: 1e7,
                prior,
            };
            let observer = std::sync::Arc::new(Observer::default());
            let r = with_progress(&observer, || map_observed(&spec, Some(observer.clone()), 0))?;
            if let Some(path) = svg {
                write_file(
                    &path,
                    &map_svg(
                        &format!("Z-width: {}", spec.scene.estimator.label()),
                        &r,
                        None,
                    )?,
                )?;
            }
            write_either(stdout, json, &r, || map_table(&r))
        }
        Command::Tune {
            scene,
            params,
            objective,
            method,
            criterion,
            search,
            solver,
            seed,
            accuracy,
            final_accuracy,
            finalists,
            replicates,
            max_evaluations,
            constraint,
            b,
            json,
            svg,
            csv,
        } => {
            let params = serde_json::from_str(&params).map_err(|e| {
                CliError::Input(format!(
                    "--params = {params:?} is not allowed: {e}; e.g. '{{\"cutoff_hz\":{{\"min\":10,\"max\":500}}}}'"
                ))
            })?;
            let objective = parse_objective("objective", &objective)?;
            let spec = crate::tune::TuneSpec {
                scene: read_scene(&scene)?,
                params,
                objective,
                method: parse_choice("method", &method)?,
                criterion: parse_choice("criterion", &criterion)?,
                search: parse_choice("search", &search)?,
                accuracy: Accuracy::Preset(parse_choice("accuracy", &accuracy)?),
                final_accuracy: Accuracy::Preset(parse_choice("final-accuracy", &final_accuracy)?),
                finalists,
                replicates,
                solver: parse_choice("solver", &solver)?,
                seed,
                max_evaluations,
                constraint: constraint
                    .map(|c| parse_choice("constraint", &c))
                    .transpose()?,
                b,
                b_max: 1000.0,
                k_max: 1e7,
            };
            let tune = spec.validate()?;
            let observer = std::sync::Arc::new(Observer::default());
            let r = with_progress(&observer, || tune.run(Some(observer.clone())))?;
            if let Some(p) = svg {
                write_file(&p, &r.svg().map_err(CliError::Failure)?)?;
            }
            if let Some(p) = csv {
                write_file(&p, &r.csv())?;
            }
            write_either(stdout, json, &r, || r.table())
        }
        Command::Compare {
            scene,
            accuracy,
            json,
            svg_dir,
            tuned,
            max_evaluations,
            seed,
            criterion,
            resolve_rounds,
        } => {
            let criterion: Criterion = parse_choice("criterion", &criterion)?;
            let spec = match &scene {
                Some(p) => read_scene(p)?,
                None => compare::seed_2018_scene(),
            };
            let acc = Accuracy::Preset(parse_choice("accuracy", &accuracy)?);
            let tuned = tuned
                .map(|o| -> Result<_, CliError> {
                    let t = crate::tune::fair::TunedCompare {
                        objective: parse_objective("tuned", &o)?,
                        max_evaluations,
                        seed,
                    };
                    t.validate().map_err(|mut e| {
                        e.field = e
                            .field
                            .replace("tuned.max_evaluations", "--max-evaluations")
                            .replace("tuned.objective", "--tuned");
                        CliError::from(e)
                    })?;
                    Ok(t)
                })
                .transpose()?;
            let rounds = compare::rounds_or_default(resolve_rounds, tuned.is_some());
            compare::check_rounds(rounds).map_err(|mut e| {
                e.field = "--resolve-rounds".into();
                CliError::from(e)
            })?;
            spec.validate()?;
            let observer = std::sync::Arc::new(Observer::default());
            let r = with_progress(&observer, || match &tuned {
                Some(t) => crate::tune::fair::compare_tuned(
                    &spec,
                    &acc,
                    criterion,
                    t,
                    rounds,
                    Some(observer.clone()),
                ),
                None => compare::compare_observed(
                    &spec,
                    &acc,
                    criterion,
                    None,
                    rounds,
                    Some(observer.clone()),
                ),
            })?;
            if let Some(dir) = svg_dir {
                std::fs::create_dir_all(&dir).map_err(|e| {
                    CliError::Failure(format!("cannot create {}: {e}", dir.display()))
                })?;
                // One colour scale for every estimator's plot, so colours
                // compare across the files.
                let scale = r.rows.iter().fold(None, |acc, row| {
                    FidelityScale::union(acc, FidelityScale::of(&plot_points(&row.map)))
                });
                for row in &r.rows {
                    let name: String = row
                        .name
                        .chars()
                        .map(|c| {
                            if c.is_ascii_alphanumeric() {
                                c.to_ascii_lowercase()
                            } else {
                                '_'
                            }
                        })
                        .collect();
                    write_file(
                        &dir.join(format!("{name}.svg")),
                        &map_svg(
                            &format!("Z-width: {} ({})", row.name, row.parameters),
                            &row.map,
                            scale,
                        )?,
                    )?;
                }
            }
            write_either(stdout, json, &r, || r.table())
        }
        Command::Bench {
            what:
                BenchCommand::Service {
                    server,
                    submissions,
                    rate,
                    seconds,
                },
        } => {
            if !(rate > 0.0
                && rate <= 10_000.0
                && seconds > 0.0
                && seconds <= 600.0
                && (1..=100_000).contains(&submissions))
            {
                return Err(CliError::Input(
                    "bench service: rate must be 0–10000 /s, seconds 0–600, submissions 1–100000"
                        .into(),
                ));
            }
            let r = client(server)?.bench(submissions, rate, seconds)?;
            write_json(stdout, &r)
        }
        Command::Bench {
            what:
                BenchCommand::Tune {
                    accuracy,
                    scan_points,
                    levant_accuracy,
                    levant_evaluations,
                    json,
                },
        } => {
            if !(5..=5000).contains(&scan_points) || !(1..=1000).contains(&levant_evaluations) {
                return Err(CliError::Input(
                    "bench tune: --scan-points must be 5 to 5000, --levant-evaluations 1 to 1000"
                        .into(),
                ));
            }
            let study = crate::tune::study::Study {
                cutoff: crate::tune::study::cutoff(
                    parse_choice("accuracy", &accuracy)?,
                    scan_points,
                )?,
                levant: crate::tune::study::levant(
                    parse_choice("levant-accuracy", &levant_accuracy)?,
                    levant_evaluations,
                )?,
            };
            write_either(stdout, json, &study, || study.table())
        }
        Command::Bench {
            what:
                BenchCommand::Scale {
                    db,
                    maps,
                    sweeps,
                    claims,
                    repeat,
                    json,
                },
        } => {
            if !(2..=1000).contains(&maps)
                || !(1..=100).contains(&sweeps)
                || !(10..=1_000_000).contains(&claims)
                || !(1..=10).contains(&repeat)
            {
                return Err(CliError::Input(format!(
                    "bench scale: --maps must be 2 to 1000 (got {maps}), --sweeps 1 to 100 (got {sweeps}), --claims 10 to 1000000 (got {claims}), --repeat 1 to 10 (got {repeat})"
                )));
            }
            let db = db_location(&db)?;
            if db.sqlite_path().is_some() {
                return Err(CliError::Input(format!(
                    "--db {db}: bench scale measures a PostgreSQL database (postgres://…)"
                )));
            }
            let rt = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
            let r = rt
                .block_on(crate::jobs::bench::run(&db, maps, sweeps, claims, repeat))
                .map_err(CliError::Failure)?;
            write_either(stdout, json, &r, || r.table())
        }
        Command::Bench {
            what:
                BenchCommand::Ui {
                    db,
                    experiments,
                    trials,
                    big,
                    repeat,
                    json,
                },
        } => {
            if !(5..=1_000_000).contains(&experiments)
                || !(1..=100_000_000).contains(&trials)
                || !(1..=1_000_000).contains(&big)
                || big > trials
                || !(1..=100).contains(&repeat)
            {
                return Err(CliError::Input(format!(
                    "bench ui: --experiments must be 5 to 1000000 (got {experiments}), --trials 1 to 100000000 (got {trials}), --big 1 to 1000000 and at most --trials (got {big}), --repeat 1 to 100 (got {repeat})"
                )));
            }
            let db = db_location(&db)?;
            let rt = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
            let r = rt
                .block_on(crate::http::ui::bench::run(
                    &db,
                    experiments,
                    trials,
                    big,
                    repeat,
                ))
                .map_err(|e| match e {
                    crate::http::ui::bench::BenchError::Input(m) => CliError::Input(m),
                    crate::http::ui::bench::BenchError::Failure(m) => CliError::Failure(m),
                })?;
            write_either(stdout, json, &r, || r.table())
        }
        Command::Bench {
            what:
                BenchCommand::Tradeoff {
                    scene,
                    search,
                    json,
                },
        } => {
            let search = parse_choice::<SearchKind>("search", &search)?;
            let rows = tradeoff::run(scene.as_deref(), search)?;
            write_either(stdout, json, &rows, || tradeoff::table(&rows))
        }
        Command::Bench {
            what: BenchCommand::Trust { json },
        } => {
            let rows = crate::zwidth::trust::run()?;
            write_either(stdout, json, &rows, || crate::zwidth::trust::table(&rows))
        }
        Command::Estimate {
            rate,
            estimator,
            quantization,
        } => {
            let sampling = Sampling::new(rate, quantization)?;
            let spec = EstimatorSpec::from_json(&estimator)?;
            let mut est = spec.build(sampling)?;
            let ys = read_samples(stdin)?;
            let mut out = BufWriter::new(stdout);
            for y in ys {
                let v = est.update(y);
                if !v.is_finite() {
                    return Err(CliError::Failure(format!(
                        "internal error: non-finite estimate for input {y}"
                    )));
                }
                writeln!(out, "{v}").map_err(io)?;
            }
            out.flush().map_err(io)
        }
        Command::Accuracy {
            rates,
            json,
            svg,
            quantization,
        } => {
            let cfg = AccuracyConfig {
                rates,
                quantization,
                ..AccuracyConfig::default()
            };
            let report = accuracy::run(&cfg)?;
            if let Some(path) = svg {
                let series: Vec<Series> = report
                    .rows
                    .iter()
                    .map(|r| {
                        Series::new(
                            r.name.clone(),
                            report
                                .rates
                                .iter()
                                .copied()
                                .zip(r.rms_error.iter().copied())
                                .collect(),
                        )
                    })
                    .collect();
                let text = loglog_svg(
                    "RMS velocity error vs sample rate (2011 paper Fig. 2 study)",
                    "sample rate (Hz)",
                    "RMS error (m/s)",
                    &series,
                )
                .map_err(CliError::Failure)?;
                std::fs::write(&path, text).map_err(|e| {
                    CliError::Failure(format!("cannot write {}: {e}", path.display()))
                })?;
            }
            if json {
                write_json(stdout, &report)
            } else {
                write!(stdout, "{}", report.table()).map_err(io)
            }
        }
        Command::Lipschitz {
            rate,
            quantization,
            json,
        } => {
            let ys = read_samples(stdin)?;
            let est = lipschitz::estimate(&ys, rate, quantization)?;
            if json {
                write_json(stdout, &est)
            } else {
                writeln!(
                    stdout,
                    "C = {:.6} m/s² (max |x''| at t = {:.6} s; window {} samples = {:.6} s; noise floor {:.3e} m/s²)\nmethod: {}",
                    est.lipschitz,
                    est.at_s,
                    2 * est.half_window + 1,
                    est.window_s,
                    est.noise_floor,
                    est.method
                )
                .map_err(io)
            }
        }
        Command::Gains { estimator, json } => {
            let spec = EstimatorSpec::from_json(&estimator)?;
            let EstimatorKind::Levant(l) = &spec.kind else {
                return Err(CliError::Input(format!(
                    "estimator.kind = {:?} is not allowed: gains are reported for kind \"levant\" only",
                    serde_json::to_value(&spec).ok().and_then(|v| v.get("kind").cloned()).unwrap_or_default()
                )));
            };
            let report = l.gains()?.report();
            if json {
                write_json(stdout, &report)
            } else {
                writeln!(stdout, "{report}").map_err(io)
            }
        }
        Command::Record {
            scene,
            out,
            duration,
            period,
            f_max,
            peak_force,
            band_min,
            band_max,
            band_force,
        } => {
            let ex = crate::identify::record::Excitation {
                period_s: period,
                f_max_hz: f_max,
                peak_force,
                duration_s: duration,
                band: match (band_min, band_max, band_force) {
                    (Some(f_min_hz), Some(f_max_hz), Some(peak_force)) => {
                        Some(crate::identify::record::Band {
                            f_min_hz,
                            f_max_hz,
                            peak_force,
                        })
                    }
                    _ => None,
                },
            };
            super::identify::run_record(&scene, ex, &out, stdout)
        }
        Command::Identify {
            trace,
            model,
            mode_trace,
            scene,
            out,
            json,
        } => super::identify::run_identify(
            &trace,
            &model,
            mode_trace.as_deref(),
            scene.as_deref(),
            out.as_deref(),
            json,
            stdout,
        ),
        other => Err(CliError::Failure(format!("{other:?} is not handled here"))),
    }
}
