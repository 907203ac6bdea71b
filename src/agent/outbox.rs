//! The agent's outbox: each result written to its own file (written to a
//! temporary name, synced, renamed) before it is sent, removed on the
//! server's `ack`; what is in it at a reconnect goes in `hello`.

use std::path::{Path, PathBuf};

use crate::rig::protocol::TrialResult;

pub struct Outbox {
    dir: PathBuf,
}

impl Outbox {
    pub fn open(dir: &Path) -> Result<Self, String> {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("--outbox {} cannot be made: {e}", dir.display()))?;
        Ok(Self { dir: dir.into() })
    }

    /// A file name for a trial id and the epoch it ran under (ids hold
    /// '/'; names do not): a result of a trial run again under a later
    /// epoch is another file, never removed by the first one's ack.
    fn path(&self, trial_id: &str, epoch: u64) -> PathBuf {
        let name: String = trial_id
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        self.dir.join(format!("{name}_{epoch}.json"))
    }

    /// Keep `r` until acknowledged (durably: synced before renamed).
    pub fn put(&self, r: &TrialResult) -> std::io::Result<()> {
        use std::io::Write;
        let path = self.path(&r.trial_id, r.epoch);
        let tmp = path.with_extension("tmp");
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(serde_json::to_string(r).unwrap_or_default().as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)?;
        if let Ok(d) = std::fs::File::open(&self.dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// Acknowledged: forget it.
    pub fn remove(&self, trial_id: &str, epoch: u64) {
        let _ = std::fs::remove_file(self.path(trial_id, epoch));
    }

    /// Everything not yet acknowledged, oldest first (unreadable files are
    /// skipped: a torn write never got renamed into place).
    pub fn all(&self) -> Vec<TrialResult> {
        let mut files: Vec<_> = std::fs::read_dir(&self.dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
            .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
            .collect();
        files.sort();
        files
            .into_iter()
            .filter_map(|(_, p)| serde_json::from_str(&std::fs::read_to_string(p).ok()?).ok())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::search::Point;

    #[test]
    fn a_result_stays_until_acknowledged() {
        let dir = std::env::temp_dir().join(format!("zwidth-outbox-{}", std::process::id()));
        let o = Outbox::open(&dir).unwrap();
        let r = TrialResult {
            epoch: 3,
            trial_id: "e/0/40a0000000000000/0000000000000000".into(),
            point: Point {
                k: 2000.0,
                stable: Some(true),
                ..Point::default()
            },
            measured: Default::default(),
        };
        o.put(&r).unwrap();
        // A second outbox on the same directory (the agent restarted) sees it.
        assert_eq!(Outbox::open(&dir).unwrap().all(), vec![r.clone()]);
        // An ack under another epoch is another result's.
        o.remove(&r.trial_id, 2);
        assert_eq!(o.all().len(), 1);
        o.remove(&r.trial_id, 3);
        assert!(o.all().is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }
}
