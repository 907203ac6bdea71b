//! The pooled interval of a finalist's replicates (issue 31).

use super::pooled_interval;

/// Issue 31: the pooled interval's half-width is t(0.975, n − 1)·s/√n
/// with the exact quantile and degrees of freedom (t(0.975, 2) =
/// 4.302652730, t(0.975, 4) = 2.776445105: scipy.stats.t.ppf), unless
/// the replicates' own intervals are wider.
#[test]
fn the_pooled_interval_is_the_t_interval_of_the_mean() {
    // Scores 10, 12, 14: mean 12, s² = 4, s/√3 = 1.1547005.
    let [lo, hi] = pooled_interval(&[10.0, 12.0, 14.0], &[[11.9, 12.1]; 3]);
    let half = 4.302_652_730 * (4.0f64 / 3.0).sqrt();
    assert!((hi - lo - 2.0 * half).abs() < 1e-8, "{lo} {hi}");
    assert!(((hi + lo) / 2.0 - 12.0).abs() < 1e-12);
    // Five replicates 1..5: mean 3, s² = 2.5, s/√5 = 0.7071068.
    let [lo, hi] = pooled_interval(&[1.0, 2.0, 3.0, 4.0, 5.0], &[[2.9, 3.1]; 5]);
    assert!(
        (hi - 3.0 - 2.776_445_105 * 0.5f64.sqrt()).abs() < 1e-8,
        "{hi}"
    );
    assert!(
        (3.0 - lo - 2.776_445_105 * 0.5f64.sqrt()).abs() < 1e-8,
        "{lo}"
    );
    // Replicates that agree: the mean of their own intervals.
    assert_eq!(
        pooled_interval(&[5.0, 5.0], &[[4.0, 6.0], [4.5, 5.5]]),
        [4.25, 5.75]
    );
    // One: its own interval.
    assert_eq!(pooled_interval(&[5.0], &[[4.0, 6.0]]), [4.0, 6.0]);
}
