//! The states an experiment is stored in: [`ExperimentState`], one Rust
//! enum written as the same lowercase words in SQLite and PostgreSQL (the
//! `state` column of `experiments`, whose CHECK lists the same words in
//! `migrations/sqlite/0001_experiments.sql` and `migrations/postgres/0001_schema.sql`), so a misspelt state is
//! a compile error rather than a row no query matches. A leaf: it imports
//! nothing of the crate.

use serde::{Deserialize, Serialize};

/// Where an experiment is in its life (docs/service.md, "States").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExperimentState {
    /// Waiting for a runner.
    Queued,
    /// Waiting for its `not_before` time.
    Scheduled,
    /// Held by a runner under a lease.
    Running,
    /// Ended with a result.
    Succeeded,
    /// Ended with an error.
    Failed,
    /// Ended by a cancel request.
    Cancelled,
    /// Stopped by a shutdown or a store fault; resumes at the next start.
    Interrupted,
}

use ExperimentState::*;

impl ExperimentState {
    /// Every state, in the order the queue and the dashboard list them.
    pub const ALL: [Self; 7] = [
        Queued,
        Scheduled,
        Running,
        Succeeded,
        Failed,
        Cancelled,
        Interrupted,
    ];

    /// The word stored in the database and shown in the API.
    pub const fn as_str(self) -> &'static str {
        match self {
            Queued => "queued",
            Scheduled => "scheduled",
            Running => "running",
            Succeeded => "succeeded",
            Failed => "failed",
            Cancelled => "cancelled",
            Interrupted => "interrupted",
        }
    }

    /// An end state: nothing runs it again.
    pub const fn ended(self) -> bool {
        matches!(self, Succeeded | Failed | Cancelled)
    }
}

impl std::fmt::Display for ExperimentState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for ExperimentState {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        ALL.iter()
            .copied()
            .find(|x| x.as_str() == s)
            .ok_or_else(|| {
                format!(
                    "state: '{s}' is not an experiment state (one of {})",
                    STATES.join(", ")
                )
            })
    }
}

/// How a row's `state` column is read (`#[sqlx(try_from = "String")]`).
impl TryFrom<String> for ExperimentState {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

const ALL: [ExperimentState; 7] = ExperimentState::ALL;

/// Every state's word, in [`ExperimentState::ALL`]'s order.
pub const STATES: [&str; 7] = [
    ALL[0].as_str(),
    ALL[1].as_str(),
    ALL[2].as_str(),
    ALL[3].as_str(),
    ALL[4].as_str(),
    ALL[5].as_str(),
    ALL[6].as_str(),
];

#[cfg(test)]
mod tests {
    use super::*;

    /// The words of the CHECK constraint on `experiments.state`, as each
    /// database's first migration spells them.
    fn checked_words(migration: &str) -> Vec<String> {
        let line = migration
            .lines()
            .find(|l| l.trim_start().starts_with("state ") && l.contains("CHECK"))
            .expect("a CHECK on state");
        let inside = &line[line.find("IN (").unwrap() + 4..line.rfind(')').unwrap() - 1];
        inside
            .split(',')
            .map(|w| w.trim().trim_matches('\'').to_string())
            .collect()
    }

    #[test]
    fn each_state_reads_back_from_its_word_and_no_other_word_reads() {
        let words = checked_words(include_str!("../../migrations/sqlite/0001_experiments.sql"));
        assert_eq!(
            words,
            checked_words(include_str!("../../migrations/postgres/0001_schema.sql"))
        );
        assert_eq!(STATES.to_vec(), words);
        for (s, w) in ALL.iter().zip(&words) {
            assert_eq!(w.parse::<ExperimentState>(), Ok(*s));
            assert_eq!(serde_json::to_string(s).unwrap(), format!("\"{w}\""));
            // Display: how messages and the API's view name it.
            assert_eq!(s.to_string(), *w);
        }
        let e = "Queued".parse::<ExperimentState>().unwrap_err();
        assert!(
            e.contains("'Queued'") && e.contains("queued, scheduled"),
            "{e}"
        );
    }

    #[test]
    fn only_succeeded_failed_and_cancelled_are_ends() {
        let ends: Vec<_> = ALL
            .iter()
            .filter(|s| s.ended())
            .map(|s| s.as_str())
            .collect();
        assert_eq!(ends, ["succeeded", "failed", "cancelled"]);
    }
}
