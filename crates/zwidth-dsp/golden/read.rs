//! Reading crates/zwidth-dsp/golden/vectors.txt and checking outputs
//! against it: shared by zwidth-dsp's own test (tests/golden.rs) and
//! zwidth-core's (`#[path]`-included in both; not a module of the crate).

use zwidth_dsp::fingerprint::Fingerprint;

pub struct Case {
    pub signal: String,
    pub estimator: String,
    pub spec: String,
    pub stride: usize,
    pub hash: u64,
    pub outputs: Vec<u64>,
}

pub struct Signal {
    pub name: String,
    pub rate_hz: f64,
    pub quantization: f64,
    pub positions: Vec<f64>,
}

pub fn hex(s: &str) -> u64 {
    u64::from_str_radix(s, 16).unwrap_or_else(|e| panic!("{s}: {e}"))
}

pub fn load() -> (Vec<Signal>, Vec<Case>) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../zwidth-dsp/golden/vectors.txt"
    );
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("zwidth-dsp golden vectors 1"));
    let (mut signals, mut cases) = (Vec::<Signal>::new(), Vec::<Case>::new());
    for line in lines {
        let w: Vec<&str> = line.split(' ').collect();
        match w[0] {
            "#" => {}
            "signal" => signals.push(Signal {
                name: w[1].into(),
                rate_hz: w[2].parse().unwrap(),
                quantization: w[3].parse().unwrap(),
                positions: Vec::with_capacity(w[4].parse().unwrap()),
            }),
            "p" => signals
                .last_mut()
                .unwrap()
                .positions
                .push(f64::from_bits(hex(w[1]))),
            "r" => {
                let n: usize = w[1].parse().unwrap();
                let y = f64::from_bits(hex(w[2]));
                signals
                    .last_mut()
                    .unwrap()
                    .positions
                    .extend(std::iter::repeat_n(y, n));
            }
            "estimator" => cases.push(Case {
                signal: signals.last().unwrap().name.clone(),
                estimator: w[1].into(),
                stride: w[2].parse().unwrap(),
                hash: hex(w[3]),
                spec: w[4..].join(" "),
                outputs: Vec::new(),
            }),
            "v" => cases.last_mut().unwrap().outputs.push(hex(w[1])),
            other => panic!("unknown line kind {other:?}"),
        }
    }
    (signals, cases)
}

/// The outputs at the case's stride and the hash of all, against the file.
pub fn check(case: &Case, v: &[f64], way: &str) {
    let hash = v
        .iter()
        .fold(Fingerprint::default(), |h, x| h.f64(*x))
        .finish();
    let at: Vec<u64> = v.iter().step_by(case.stride).map(|x| x.to_bits()).collect();
    if let Some(i) = at.iter().zip(&case.outputs).position(|(a, b)| a != b) {
        panic!(
            "{} on {} through {way}: output {} is {:016x} ({:e}), the vectors say {:016x} ({:e})",
            case.estimator,
            case.signal,
            i * case.stride,
            at[i],
            f64::from_bits(at[i]),
            case.outputs[i],
            f64::from_bits(case.outputs[i])
        );
    }
    assert_eq!(
        at.len(),
        case.outputs.len(),
        "{} on {}",
        case.estimator,
        case.signal
    );
    assert_eq!(
        hash, case.hash,
        "{} on {} through {way}: the hash",
        case.estimator, case.signal
    );
}
