//! A recorded open-loop trace: time, force command and encoder position,
//! one row per encoder sample, as CSV with the header `t_s,force_n,position_m`.
//!
//! Convention (what `zwidth record` writes and `zwidth identify` assumes):
//! row k holds the position read at `t_k` and the force commanded from `t_k`
//! until the next row (zero-order hold), as a rig's servo loop does.

use crate::error::SpecError;

/// The columns, in order.
pub const HEADER: &str = "t_s,force_n,position_m";
const COLUMNS: [&str; 3] = ["t_s", "force_n", "position_m"];
/// Fewest samples a trace may have.
pub const MIN_SAMPLES: usize = 1000;
/// Largest deviation of one sample interval from the trace's mean interval.
pub const EVEN_TOLERANCE: f64 = 1e-3;
/// A command at its extreme on more than this share of samples is clipped.
pub const SATURATED_SHARE: f64 = 0.01;
/// The physical range of each column, |value| at most (s, N, m): a haptic
/// device's trace lies far inside it, and a value beyond it (a logger's
/// overflow, a unit mix-up) is refused at its line before any fit, where
/// it would overflow the sums (docs/identify.md, "What a trace may hold").
pub const RANGE: [f64; 3] = [1e6, 1e5, 100.0];
/// The force command must reach this (N) somewhere, and the handle move
/// at least this far (m): below, the fit's sums underflow.
pub const MIN_PEAK_FORCE_N: f64 = 1e-6;
pub const MIN_TRAVEL_M: f64 = 1e-9;

/// An evenly sampled trace (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Sample period (s).
    pub dt: f64,
    pub t: Vec<f64>,
    pub force: Vec<f64>,
    pub position: Vec<f64>,
}

fn at(line: usize, column: usize) -> String {
    format!(
        "trace line {line}, column {} ({})",
        column + 1,
        COLUMNS[column]
    )
}

impl Trace {
    /// Parse and check a trace: the header, three finite numbers per row,
    /// even sampling, enough samples, an unclipped force command. Errors
    /// name the line (1-based, the header is line 1) and the column.
    pub fn parse_csv(text: &str) -> Result<Trace, SpecError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (hl, header) = lines.next().ok_or_else(|| {
            SpecError::new(
                "trace",
                "(empty)",
                format!("needs the header {HEADER} and at least {MIN_SAMPLES} rows"),
            )
        })?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        if names != COLUMNS {
            return Err(SpecError::new(
                format!("trace line {hl} (header)"),
                header,
                format!("must be {HEADER}: time (s), force command (N), encoder position (m)"),
            ));
        }
        let (mut t, mut force, mut position) = (Vec::new(), Vec::new(), Vec::new());
        let mut line_of = Vec::new();
        for (ln, row) in lines {
            let fields: Vec<&str> = row.split(',').map(str::trim).collect();
            if fields.len() != 3 {
                return Err(SpecError::new(
                    format!("trace line {ln}"),
                    row,
                    format!("must have 3 columns ({HEADER}), not {}", fields.len()),
                ));
            }
            let mut v = [0.0; 3];
            for (c, f) in fields.iter().enumerate() {
                v[c] = match f.parse::<f64>() {
                    Ok(x) if x.is_finite() && x.abs() <= RANGE[c] => x,
                    Ok(x) if x.is_finite() => {
                        return Err(SpecError::new(
                            at(ln, c),
                            f,
                            format!(
                                "must be within ±{:e} {} (the physical range of a trace's {})",
                                RANGE[c],
                                ["s", "N", "m"][c],
                                COLUMNS[c]
                            ),
                        ))
                    }
                    _ => {
                        return Err(SpecError::new(
                            at(ln, c),
                            f,
                            "must be a finite number (SI units)",
                        ))
                    }
                };
            }
            // Time stops increasing here: named at this line, not at the end.
            if t.last().is_some_and(|&prev| v[0] <= prev) {
                return Err(SpecError::new(at(ln, 0), fields[0], "times must increase"));
            }
            t.push(v[0]);
            force.push(v[1]);
            position.push(v[2]);
            line_of.push(ln);
        }
        let n = t.len();
        if n < MIN_SAMPLES {
            return Err(SpecError::new(
                "trace",
                format!("{n} rows"),
                format!("needs at least {MIN_SAMPLES} evenly spaced samples (record 10 s or more)"),
            ));
        }
        // Positive: the times increase (checked row by row above).
        let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
        for i in 1..n {
            let step = t[i] - t[i - 1];
            if (step - dt).abs() > EVEN_TOLERANCE * dt {
                return Err(SpecError::new(
                    at(line_of[i], 0),
                    t[i],
                    format!(
                        "is {step:e} s after the previous sample, but the trace's sample interval is {dt:e} s: the samples must be evenly spaced (within {} %); resample the trace first",
                        EVEN_TOLERANCE * 100.0
                    ),
                ));
            }
        }
        let peak = force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
        if peak < MIN_PEAK_FORCE_N {
            return Err(SpecError::new(
                format!("trace column 2 ({})", COLUMNS[1]),
                format!("peak {peak:e} N"),
                format!("the force command must reach {MIN_PEAK_FORCE_N:e} N somewhere: a smaller excitation cannot be identified"),
            ));
        }
        let (lo, hi) = position
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            });
        if hi - lo < MIN_TRAVEL_M {
            return Err(SpecError::new(
                format!("trace column 3 ({})", COLUMNS[2]),
                format!("travel {:e} m", hi - lo),
                format!("the handle must move at least {MIN_TRAVEL_M:e} m"),
            ));
        }
        let trace = Trace {
            dt,
            t,
            force,
            position,
        };
        if let Some((i, peak, count)) = trace.clipped() {
            return Err(SpecError::new(
                at(line_of[i], 1),
                peak,
                format!(
                    "is the force command's extreme on {count} of {n} samples: the command looks clipped (saturated), so the device did not feel it; identify needs an unsaturated excitation such as `zwidth record`'s multisine"
                ),
            ));
        }
        Ok(trace)
    }

    /// The first sample of a clipped command, its value and how many samples
    /// sit at ±max|F| (None when at most 1 % do).
    fn clipped(&self) -> Option<(usize, f64, usize)> {
        let peak = self.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
        if peak == 0.0 {
            return None;
        }
        let at_peak: Vec<usize> = (0..self.force.len())
            .filter(|&i| self.force[i].abs() >= peak * (1.0 - 1e-9))
            .collect();
        (at_peak.len() as f64 > SATURATED_SHARE * self.force.len() as f64)
            .then(|| (at_peak[0], self.force[at_peak[0]], at_peak.len()))
    }

    /// Sample rate (Hz).
    pub fn sample_hz(&self) -> f64 {
        1.0 / self.dt
    }

    /// The CSV text `parse_csv` reads (full precision).
    pub fn to_csv(&self) -> String {
        let mut s = String::with_capacity(self.t.len() * 48);
        s.push_str(HEADER);
        s.push('\n');
        for i in 0..self.t.len() {
            s.push_str(&format!(
                "{},{},{}\n",
                self.t[i], self.force[i], self.position[i]
            ));
        }
        s
    }

    /// The encoder step: the largest `d` such that every position is a
    /// whole multiple of it (within 1e-3 of a step, below 1e9 steps), searched as the smallest
    /// nonzero position change divided by 1…10; 0 when there is none (an
    /// unquantized sensor).
    pub fn quantization(&self) -> f64 {
        let smallest = self
            .position
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .filter(|&d| d > 0.0)
            .fold(f64::INFINITY, f64::min);
        if !smallest.is_finite() {
            return 0.0;
        }
        (1..=10)
            .map(|k| smallest / k as f64)
            .find(|&step| {
                self.position.iter().all(|&x| {
                    let r = x / step;
                    r.abs() < 1e9 && (r - r.round()).abs() <= 1e-3
                })
            })
            // Ten significant digits: 1e-6, not 9.999999999992654e-7.
            .map_or(0.0, |step| format!("{step:.9e}").parse().unwrap_or(step))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` rows at 1 kHz: a 1 µm-quantized 2 Hz sine under a 1 Hz force.
    fn csv(n: usize, edit: impl Fn(usize, String) -> String) -> String {
        let mut s = format!("{HEADER}\n");
        for k in 0..n {
            let t = k as f64 * 1e-3;
            let x = ((1e-3 * (4.0 * std::f64::consts::PI * t).sin()) / 1e-6).round() * 1e-6;
            s.push_str(&edit(
                k,
                format!("{t},{},{x}\n", (2.0 * std::f64::consts::PI * t).sin()),
            ));
        }
        s
    }

    fn err(text: &str) -> SpecError {
        Trace::parse_csv(text).unwrap_err()
    }

    #[test]
    fn round_trips_and_reads_the_encoder_step() {
        let tr = Trace::parse_csv(&csv(2000, |_, r| r)).unwrap();
        assert!((tr.dt - 1e-3).abs() < 1e-15 && (tr.sample_hz() - 1000.0).abs() < 1e-9);
        let again = Trace::parse_csv(&tr.to_csv()).unwrap();
        assert_eq!(
            (&again.t, &again.force, &again.position),
            (&tr.t, &tr.force, &tr.position)
        );
        assert_eq!(tr.quantization(), 1e-6);
        // Comments and blank lines are skipped.
        let noted = format!("# from the rig\n\n{}", csv(2000, |_, r| r));
        assert_eq!(Trace::parse_csv(&noted).unwrap().t.len(), 2000);
    }

    #[test]
    fn encoder_step_is_the_largest_common_step() {
        let mut tr = Trace::parse_csv(&csv(2000, |_, r| r)).unwrap();
        // Positions on a 2 µm grid whose smallest move is 4 µm: the step is 2 µm.
        tr.position = (0..2000)
            .map(|k| [0.0, 4e-6, 10e-6, 14e-6][k % 4])
            .collect();
        assert_eq!(tr.quantization(), 2e-6);
        // Unquantized positions: 0.
        tr.position = (0..2000).map(|k| (k as f64 * 0.37).sin() * 1e-3).collect();
        assert_eq!(tr.quantization(), 0.0);
        tr.position = vec![0.5; 2000];
        assert_eq!(tr.quantization(), 0.0);
    }

    #[test]
    fn bad_traces_name_the_line_and_column() {
        let e = err("time,force,position\n1,2,3\n");
        assert_eq!(
            (e.field.as_str(), e.value.as_str()),
            ("trace line 1 (header)", "time,force,position")
        );
        assert!(e.allowed.contains(HEADER));
        assert_eq!(err("").field, "trace");
        // Line numbers count the header as line 1: row k is line k + 2.
        let e = err(&csv(
            2000,
            |k, r| if k == 7 { "0.007,1\n".into() } else { r },
        ));
        assert_eq!(e.field, "trace line 9");
        assert!(
            e.allowed.contains("3 columns") && e.allowed.contains("not 2"),
            "{e}"
        );
        let e = err(&csv(
            2000,
            |k, r| if k == 10 { "0.01,NaN,0\n".into() } else { r },
        ));
        assert_eq!(
            (e.field.as_str(), e.value.as_str()),
            ("trace line 12, column 2 (force_n)", "NaN")
        );
        let e = err(&csv(2000, |k, r| {
            if k == 3 {
                "0.003,0,1e400\n".into()
            } else {
                r
            }
        }));
        assert_eq!(e.field, "trace line 5, column 3 (position_m)");
        let e = err(&csv(
            2000,
            |k, r| if k == 4 { "0.004,0,abc\n".into() } else { r },
        ));
        assert_eq!(
            (e.field.as_str(), e.value.as_str()),
            ("trace line 6, column 3 (position_m)", "abc")
        );
        // Too short.
        assert_eq!(
            Trace::parse_csv(&csv(1000, |_, r| r)).unwrap().t.len(),
            1000
        );
        let e = err(&csv(999, |_, r| r));
        assert_eq!((e.field.as_str(), e.value.as_str()), ("trace", "999 rows"));
        // A late sample: uneven spacing, named at its line.
        let e = err(&csv(
            2000,
            |k, r| if k == 500 { "0.5005,0,0\n".into() } else { r },
        ));
        assert_eq!(e.field, "trace line 502, column 1 (t_s)");
        assert!(e.allowed.contains("evenly spaced"), "{e}");
        // Time running backwards.
        let e = err(&csv(2000, |k, r| {
            r.replacen(
                &format!("{}", k as f64 * 1e-3),
                &format!("{}", -(k as f64) * 1e-3),
                1,
            )
        }));
        assert!(
            e.field.ends_with("column 1 (t_s)") && e.allowed.contains("increase"),
            "{e}"
        );
        // A clipped command: ±0.8 N flat tops on a sine of amplitude 1.
        let e = err(&csv(2000, |k, r| {
            let f = (2.0 * std::f64::consts::PI * k as f64 * 1e-3)
                .sin()
                .clamp(-0.8, 0.8);
            let mut c: Vec<String> = r.trim().split(',').map(String::from).collect();
            c[1] = format!("{f}");
            c.join(",") + "\n"
        }));
        assert!(
            e.field.ends_with("column 2 (force_n)") && e.allowed.contains("clipped"),
            "{e}"
        );
        assert_eq!(e.value, "0.8");
        // The first clipped sample, 1 Hz sine reaches 0.8 at t = asin(0.8)/2π ≈ 0.1476 s: row 148, line 150.
        assert_eq!(e.field, "trace line 150, column 2 (force_n)");
    }

    /// Issue 30, defect 11: a value beyond the documented range (`RANGE`) is
    /// refused at its line and column wherever it is (a 1e308 force was
    /// accepted silently in 154 of 200 places); time that stops increasing
    /// is named where it stops; a trace too small to fit is refused.
    #[test]
    fn extreme_values_are_refused_at_their_line() {
        for row in [0, 1, 7, 500, 1998, 1999] {
            for (col, value) in [
                (1, "1e308"),
                (2, "1e308"),
                (1, "-100001"),
                (2, "100.5"),
                (0, "1e7"),
            ] {
                let e = err(&csv(2000, |k, r| {
                    if k != row {
                        return r;
                    }
                    let mut c: Vec<String> = r.trim().split(',').map(String::from).collect();
                    c[col] = value.into();
                    c.join(",") + "\n"
                }));
                assert_eq!(e.field, at(row + 2, col), "row {row}: {e}");
                assert_eq!(e.value, value);
                assert!(e.allowed.contains(&format!("±{:e}", RANGE[col])), "{e}");
            }
        }
        // Not a number or infinite: said so, not "out of range".
        for bad in ["inf", "-inf", "NaN"] {
            let e = err(&csv(2000, |k, r| {
                if k == 3 {
                    format!("0.003,{bad},0\n")
                } else {
                    r
                }
            }));
            assert_eq!(
                (e.field.as_str(), e.allowed.as_str()),
                (
                    "trace line 5, column 2 (force_n)",
                    "must be a finite number (SI units)"
                )
            );
        }
        // A trace that starts late: the interval is the span over the rows.
        let late = csv(2000, |_, r| {
            let mut c: Vec<String> = r.trim().split(',').map(String::from).collect();
            c[0] = format!("{}", 5.0 + c[0].parse::<f64>().unwrap());
            c.join(",") + "\n"
        });
        let tr = Trace::parse_csv(&late).unwrap();
        assert!((tr.dt - 1e-3).abs() < 1e-12, "{}", tr.dt);
        // The least force and travel accepted: exactly at the bounds.
        let edge = |force: f64, x: f64| {
            Trace::parse_csv(&csv(2000, |k, r| {
                let mut c: Vec<String> = r.trim().split(',').map(String::from).collect();
                c[1] = format!("{:e}", if k == 7 { force } else { 0.0 });
                c[2] = format!("{:e}", if k == 9 { x } else { 0.0 });
                c.join(",") + "\n"
            }))
        };
        assert!(edge(MIN_PEAK_FORCE_N, MIN_TRAVEL_M).is_ok());
        assert_eq!(
            edge(MIN_PEAK_FORCE_N * 0.999, MIN_TRAVEL_M)
                .unwrap_err()
                .field,
            "trace column 2 (force_n)"
        );
        assert_eq!(
            edge(MIN_PEAK_FORCE_N, MIN_TRAVEL_M * 0.999)
                .unwrap_err()
                .field,
            "trace column 3 (position_m)"
        );
        // Just inside the range is a number like any other.
        let ok = Trace::parse_csv(&csv(2000, |k, r| {
            if k == 9 {
                "0.009,99999,0\n".into()
            } else {
                r
            }
        }));
        assert_eq!(ok.unwrap().force[9], 99999.0);
        // A constant time column: named at its second row (line 3), not the last.
        let e = err(&csv(2000, |k, r| {
            let mut c: Vec<String> = r.trim().split(',').map(String::from).collect();
            c[0] = "0.5".into();
            let _ = k;
            c.join(",") + "\n"
        }));
        assert_eq!(
            (e.field.as_str(), e.allowed.as_str()),
            ("trace line 3, column 1 (t_s)", "times must increase")
        );
        // Forces ×1e-300 and positions ×1e-300: nothing to identify.
        let tiny = |col: usize| {
            err(&csv(2000, |_, r| {
                let mut c: Vec<String> = r.trim().split(',').map(String::from).collect();
                let v: f64 = c[col].parse().unwrap();
                c[col] = format!("{:e}", v * 1e-300);
                c.join(",") + "\n"
            }))
        };
        let e = tiny(1);
        assert_eq!(e.field, "trace column 2 (force_n)");
        assert!(e.allowed.contains("1e-6 N"), "{e}");
        let e = tiny(2);
        assert_eq!(e.field, "trace column 3 (position_m)");
        assert!(
            !e.to_string().contains("NaN") && !e.to_string().contains("inf"),
            "{e}"
        );
    }
}
