//! A recurring daily window, e.g. overnight `{"start":"22:00","end":"06:00",
//! "tz":"Europe/Berlin"}`: outside it a rig starts nothing new (a running
//! experiment finishes). Times are wall-clock times in the zone, so the
//! window follows daylight saving time; `start > end` wraps past midnight.

use jiff::civil::Time;
use jiff::tz::TimeZone;
use jiff::Timestamp;
use serde::{Deserialize, Serialize};

use crate::error::SpecError;

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// Local wall-clock time the window opens, "HH:MM".
    pub start: String,
    /// Local wall-clock time it closes, "HH:MM" (before `start`: the next day).
    pub end: String,
    /// IANA time zone, e.g. "Europe/Berlin"; default "UTC".
    #[serde(default = "utc")]
    pub tz: String,
}

fn utc() -> String {
    "UTC".into()
}

/// A validated window.
#[derive(Debug, Clone)]
pub struct OpenHours {
    start: Time,
    end: Time,
    tz: TimeZone,
}

fn hhmm(field: &str, s: &str) -> Result<Time, SpecError> {
    let bad = || {
        SpecError::new(
            field,
            format!("{s:?}"),
            "must be a time \"HH:MM\" (00:00 to 23:59)",
        )
    };
    let (h, m) = s.split_once(':').ok_or_else(bad)?;
    if h.len() != 2 || m.len() != 2 {
        return Err(bad());
    }
    let (h, m): (i8, i8) = (h.parse().map_err(|_| bad())?, m.parse().map_err(|_| bad())?);
    Time::new(h, m, 0, 0).map_err(|_| bad())
}

impl Window {
    pub fn validate(&self) -> Result<OpenHours, SpecError> {
        let start = hhmm("window.start", &self.start)?;
        let end = hhmm("window.end", &self.end)?;
        if start == end {
            return Err(SpecError::new(
                "window.end",
                format!("{:?}", self.end),
                "must differ from window.start (leave the window out to run at any time)",
            ));
        }
        let tz = TimeZone::get(&self.tz).map_err(|_| {
            SpecError::new(
                "window.tz",
                format!("{:?}", self.tz),
                "must be an IANA time zone such as \"Europe/Berlin\" or \"UTC\"",
            )
        })?;
        Ok(OpenHours { start, end, tz })
    }
}

impl OpenHours {
    /// Whether a rig may start an experiment at `now`.
    pub fn is_open(&self, now: Timestamp) -> bool {
        let t = now.to_zoned(self.tz.clone()).time();
        if self.start < self.end {
            self.start <= t && t < self.end
        } else {
            t >= self.start || t < self.end
        }
    }

    /// The next time the window opens after `now` (`now` itself when open).
    pub fn next_open(&self, now: Timestamp) -> Timestamp {
        if self.is_open(now) {
            return now;
        }
        let z = now.to_zoned(self.tz.clone());
        let mut day = z.date();
        for _ in 0..3 {
            // A start inside a DST gap resolves to the later valid instant.
            if let Ok(at) = day.to_datetime(self.start).to_zoned(self.tz.clone()) {
                if at.timestamp() > now {
                    return at.timestamp();
                }
            }
            match day.tomorrow() {
                Ok(d) => day = d,
                Err(_) => break,
            }
        }
        now
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn w(start: &str, end: &str, tz: &str) -> OpenHours {
        Window {
            start: start.into(),
            end: end.into(),
            tz: tz.into(),
        }
        .validate()
        .unwrap()
    }

    fn ts(s: &str) -> Timestamp {
        s.parse().unwrap()
    }

    #[test]
    fn overnight_window_follows_berlin_daylight_saving() {
        // Central European Time is UTC+1 in winter, UTC+2 in summer (EU
        // directive 2000/84/EC: last Sunday of March to last Sunday of October).
        let o = w("22:00", "06:00", "Europe/Berlin");
        assert!(o.is_open(ts("2026-11-22T21:30:00Z"))); // 22:30 CET
        assert!(!o.is_open(ts("2026-11-22T20:30:00Z"))); // 21:30 CET
        assert!(o.is_open(ts("2026-11-23T04:59:00Z"))); // 05:59 CET
        assert!(!o.is_open(ts("2026-11-23T05:00:00Z"))); // 06:00 CET
        assert!(o.is_open(ts("2026-07-01T20:30:00Z"))); // 22:30 CEST
        assert!(!o.is_open(ts("2026-07-01T19:30:00Z"))); // 21:30 CEST
        assert_eq!(
            o.next_open(ts("2026-11-22T12:00:00Z")),
            ts("2026-11-22T21:00:00Z")
        );
        assert_eq!(
            o.next_open(ts("2026-07-01T12:00:00Z")),
            ts("2026-07-01T20:00:00Z")
        );
        let now = ts("2026-11-22T23:00:00Z");
        assert_eq!(o.next_open(now), now);
    }

    #[test]
    fn daytime_window_and_bad_windows() {
        let o = w("09:00", "17:30", "UTC");
        assert!(o.is_open(ts("2026-11-22T17:29:00Z")));
        assert!(!o.is_open(ts("2026-11-22T17:30:00Z")));
        assert_eq!(
            o.next_open(ts("2026-11-22T18:00:00Z")),
            ts("2026-11-23T09:00:00Z")
        );
        let bad = |s: &str, e: &str, tz: &str| {
            Window {
                start: s.into(),
                end: e.into(),
                tz: tz.into(),
            }
            .validate()
            .unwrap_err()
            .field
        };
        assert_eq!(bad("24:00", "06:00", "UTC"), "window.start");
        assert_eq!(bad("22:00", "6:00", "UTC"), "window.end");
        assert_eq!(bad("22:00", "22:00", "UTC"), "window.end");
        assert_eq!(bad("22:00", "06:00", "Mars/Olympus"), "window.tz");
    }
}
