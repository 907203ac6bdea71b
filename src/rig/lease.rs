//! The server's lease on an attached rig, as a pure state machine (no I/O,
//! time passed in): one live session per rig, each under its own epoch;
//! one trial out at a time, remembered with the epoch it was sent under; a
//! result counts only under that epoch. `attached.rs` drives it from the
//! WebSocket and the searches; the property test below checks it.

use super::protocol::RigState;

/// Timings of a lease (ms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Heartbeat interval asked of the agent.
    pub heartbeat_ms: u64,
    /// Silence after which the rig is `lost_contact` (nothing new is sent).
    pub ttl_ms: u64,
    /// Further silence after which the session is fenced off: its epoch
    /// ends and the trial it held is sent again to the next session.
    pub grace_ms: u64,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            heartbeat_ms: 2_000,
            ttl_ms: 10_000,
            grace_ms: 20_000,
        }
    }
}

/// The live session.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    pub epoch: u64,
    pub agent: String,
    pub boot: String,
    pub last_heard_ms: i64,
    pub state: RigState,
}

/// The trial out on the rig (or waiting to go out).
#[derive(Debug, Clone, PartialEq)]
pub struct Outstanding {
    pub trial_id: String,
    /// The epoch it was sent under; None: not sent (or to be sent again).
    pub sent_epoch: Option<u64>,
    pub sent_ms: i64,
    /// Not to be sent again before this (after a refusal: the agent busy
    /// finishing a cancelled trial is not asked again at once).
    pub retry_at_ms: i64,
}

/// Why the server will not take a result (it goes to the audit).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// No trial with this id is out.
    NotSent,
    /// The trial is out under another epoch (it was sent again, or the
    /// result comes from a session since fenced off).
    StaleEpoch { sent: Option<u64> },
}

impl Refusal {
    pub fn describe(&self, epoch: u64) -> String {
        match self {
            Refusal::NotSent => "a result for a trial that is not out".into(),
            Refusal::StaleEpoch { sent: Some(s) } => {
                format!("stale epoch {epoch}: the trial is out under epoch {s}")
            }
            Refusal::StaleEpoch { sent: None } => {
                format!("stale epoch {epoch}: the trial was fenced off and waits to be sent again")
            }
        }
    }
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Lease {
    pub timing: Timing,
    pub session: Option<Session>,
    pub outstanding: Option<Outstanding>,
    /// Why the rig takes no trials until an operator lifts it.
    pub quarantine: Option<String>,
    /// Why the rig takes no new trials now: its window is closed.
    pub window_closed: Option<String>,
    /// Since when the live session has been silent past the TTL.
    pub lost_since_ms: Option<i64>,
    /// The highest epoch handed out (sessions with lower ones are fenced).
    pub highest_epoch: u64,
    /// When the last session's link closed (its trial is fenced off after
    /// TTL + grace unless a session takes its result first).
    pub closed_ms: Option<i64>,
}

impl Lease {
    pub fn new(timing: Timing) -> Self {
        Self {
            timing,
            ..Self::default()
        }
    }

    /// Whether a session is live and heard from within the TTL.
    pub fn connected(&self, now_ms: i64) -> bool {
        self.session
            .as_ref()
            .is_some_and(|s| now_ms - s.last_heard_ms <= self.timing.ttl_ms as i64)
    }

    /// A new session under `epoch` (from the database's counter, so larger
    /// than any before). Refused (Err: why) while another session is live
    /// and heard within the TTL; a silent one is replaced (fenced).
    /// Then the results the agent lists as unacknowledged are checked
    /// (they may be for the trial out, under its epoch), and then
    /// [`Lease::resume`].
    pub fn open(
        &mut self,
        epoch: u64,
        agent: &str,
        boot: &str,
        state: RigState,
        now_ms: i64,
    ) -> Result<(), String> {
        if epoch <= self.highest_epoch {
            return Err(format!(
                "epoch {epoch} is not above {}: refused",
                self.highest_epoch
            ));
        }
        if let Some(s) = &self.session {
            if self.connected(now_ms) {
                return Err(format!(
                    "the rig already has a live session (agent {}, epoch {}); one session per rig",
                    s.agent, s.epoch
                ));
            }
        }
        self.highest_epoch = epoch;
        self.closed_ms = None;
        self.session = Some(Session {
            epoch,
            agent: agent.to_string(),
            boot: boot.to_string(),
            last_heard_ms: now_ms,
            state,
        });
        self.lost_since_ms = None;
        Ok(())
    }

    /// After `hello`'s results: a trial still out that the agent is not
    /// `running` was lost with the agent (killed before it finished): it
    /// is sent again, under the new epoch.
    pub fn resume(&mut self, running: Option<&str>) {
        if let Some(o) = &mut self.outstanding {
            if running != Some(o.trial_id.as_str()) {
                o.sent_epoch = None;
            }
        }
    }

    /// A message under `epoch` arrived: the session is alive. False when
    /// the epoch is not the live session's (the message is stale).
    pub fn heard(&mut self, epoch: u64, state: Option<RigState>, now_ms: i64) -> bool {
        match &mut self.session {
            Some(s) if s.epoch == epoch => {
                s.last_heard_ms = now_ms;
                if let Some(st) = state {
                    s.state = st;
                }
                self.lost_since_ms = None;
                true
            }
            _ => false,
        }
    }

    /// Time passes: past the TTL the rig is lost (nothing new is sent);
    /// past TTL + grace the session is fenced off (Some(epoch) to close)
    /// and its trial waits to be sent again.
    pub fn tick(&mut self, now_ms: i64) -> Option<u64> {
        let limit = (self.timing.ttl_ms + self.timing.grace_ms) as i64;
        if self.session.is_none() {
            if let (Some(closed), Some(o)) = (self.closed_ms, &mut self.outstanding) {
                if now_ms - closed > limit {
                    o.sent_epoch = None;
                    self.closed_ms = None;
                }
            }
            return None;
        }
        let s = self.session.as_ref()?;
        let silent = now_ms - s.last_heard_ms;
        if silent <= self.timing.ttl_ms as i64 {
            return None;
        }
        self.lost_since_ms
            .get_or_insert(s.last_heard_ms + self.timing.ttl_ms as i64);
        if silent <= limit {
            return None;
        }
        let epoch = s.epoch;
        self.fence(epoch);
        Some(epoch)
    }

    /// End the session under `epoch` and fence it off: a trial it held
    /// is sent again, and its late result is refused.
    pub fn fence(&mut self, epoch: u64) {
        if self.session.as_ref().is_some_and(|s| s.epoch == epoch) {
            self.session = None;
            self.lost_since_ms = None;
        }
        if let Some(o) = &mut self.outstanding {
            if o.sent_epoch == Some(epoch) {
                o.sent_epoch = None;
            }
        }
    }

    /// The link of the session under `epoch` closed: no session, but the
    /// trial it held stays out under its epoch (the agent finishes it and
    /// lists the result in its next `hello`), until the grace runs out.
    pub fn closed(&mut self, epoch: u64, now_ms: i64) {
        if self.session.as_ref().is_some_and(|s| s.epoch == epoch) {
            self.session = None;
            self.lost_since_ms = None;
            self.closed_ms = Some(now_ms);
        }
    }

    /// Why nothing may be sent now, or None when a trial may go out.
    pub fn blocked(&self, now_ms: i64) -> Option<String> {
        if let Some(q) = &self.quarantine {
            return Some(format!("quarantined: {q}"));
        }
        if let Some(w) = &self.window_closed {
            return Some(format!("waiting for the rig: {w}"));
        }
        let Some(s) = &self.session else {
            return Some("waiting for the rig: no agent connected".into());
        };
        if !self.connected(now_ms) {
            return Some(format!(
                "waiting for the rig: lost contact (silent {} ms)",
                now_ms - s.last_heard_ms
            ));
        }
        if !s.state.armed() {
            return Some(format!("waiting for the rig: {}", s.state.describe()));
        }
        None
    }

    /// Put `trial_id` out (or keep it out): Some(epoch) when it is to be
    /// sent now under that epoch; None when it is out already, or when
    /// nothing may be sent.
    pub fn send(&mut self, trial_id: &str, now_ms: i64) -> Option<u64> {
        if let Some(o) = &self.outstanding {
            if o.trial_id == trial_id {
                if o.sent_epoch.is_some() || now_ms < o.retry_at_ms {
                    return None;
                }
            } else if o.sent_epoch.is_some() {
                // Another trial is out on the rig (one at a time): it ends
                // first. One that is not out (a search since cancelled) is
                // replaced.
                return None;
            }
        }
        // Past its retry time (checked above): nothing to keep of it.
        if self.blocked(now_ms).is_some() {
            self.outstanding = Some(Outstanding {
                trial_id: trial_id.to_string(),
                sent_epoch: None,
                sent_ms: now_ms,
                retry_at_ms: now_ms,
            });
            return None;
        }
        let epoch = self.session.as_ref()?.epoch;
        self.outstanding = Some(Outstanding {
            trial_id: trial_id.to_string(),
            sent_epoch: Some(epoch),
            sent_ms: now_ms,
            retry_at_ms: now_ms,
        });
        Some(epoch)
    }

    /// A result arrived: Ok when it is for the trial out and carries the
    /// epoch it was sent under (store it, then [`Lease::done`]).
    pub fn check_result(&self, epoch: u64, trial_id: &str) -> Result<(), Refusal> {
        match &self.outstanding {
            Some(o) if o.trial_id == trial_id => {
                if o.sent_epoch == Some(epoch) {
                    Ok(())
                } else {
                    Err(Refusal::StaleEpoch { sent: o.sent_epoch })
                }
            }
            _ => Err(Refusal::NotSent),
        }
    }

    /// The trial's result is committed (or the trial is withdrawn).
    pub fn done(&mut self, trial_id: &str) {
        if self
            .outstanding
            .as_ref()
            .is_some_and(|o| o.trial_id == trial_id)
        {
            self.outstanding = None;
        }
    }

    /// The agent refused the trial under `epoch`: it waits to be sent
    /// again (to a session that can run it), not before one heartbeat.
    pub fn refused(&mut self, epoch: u64, trial_id: &str, now_ms: i64) {
        if let Some(o) = &mut self.outstanding {
            if o.trial_id == trial_id && o.sent_epoch == Some(epoch) {
                o.sent_epoch = None;
                o.retry_at_ms = now_ms + self.timing.heartbeat_ms as i64;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[derive(Debug, Clone)]
    enum Op {
        /// A new session (the next epoch) with this state.
        Open(u8),
        /// A message under the n-th epoch handed out (from the end).
        Heard(u8, Option<u8>),
        Advance(u16),
        Tick,
        Close(u8),
        Send(u8),
        Result(u8, u8),
        Refused(u8, u8),
        Quarantine(bool),
    }

    fn state(s: u8) -> RigState {
        match s % 5 {
            0 | 1 => RigState::Armed,
            2 => RigState::Disarmed,
            3 => RigState::EStop,
            _ => RigState::OperatorLocked {
                user: "op".into(),
                note: "n".into(),
                until_ms: None,
            },
        }
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            any::<u8>().prop_map(Op::Open),
            (any::<u8>(), proptest::option::of(any::<u8>())).prop_map(|(e, s)| Op::Heard(e, s)),
            (0u16..800).prop_map(Op::Advance),
            Just(Op::Tick),
            any::<u8>().prop_map(Op::Close),
            (0u8..3).prop_map(Op::Send),
            (0u8..3, any::<u8>()).prop_map(|(t, e)| Op::Result(t, e)),
            (0u8..3, any::<u8>()).prop_map(|(t, e)| Op::Refused(t, e)),
            any::<bool>().prop_map(Op::Quarantine),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        /// Whatever the agents, links and clocks do: a result is taken only
        /// under the epoch its trial was last sent with (so no trial is out
        /// under two live epochs), none is taken twice, and nothing is sent
        /// while the rig is disarmed, locked, e-stopped, quarantined, lost
        /// or without a session.
        #[test]
        fn the_lease_never_takes_a_stale_or_second_result(ops in proptest::collection::vec(op(), 1..120)) {
            let timing = Timing { heartbeat_ms: 100, ttl_ms: 500, grace_ms: 500 };
            let mut l = Lease::new(timing);
            let mut now = 0i64;
            let mut epochs: Vec<u64> = vec![0];
            let mut last_sent: [Option<u64>; 3] = [None; 3];
            let mut stored = [false; 3];
            let pick = |epochs: &Vec<u64>, n: u8| epochs[epochs.len() - 1 - (n as usize % epochs.len())];
            for op in ops {
                match op {
                    Op::Open(s) => {
                        let e = epochs.last().unwrap() + 1;
                        epochs.push(e);
                        let _ = l.open(e, "a", "b", state(s), now);
                        // `hello` says which trial it runs: none here.
                        if l.session.as_ref().is_some_and(|x| x.epoch == e) {
                            l.resume(None);
                        }
                    }
                    Op::Heard(n, s) => { l.heard(pick(&epochs, n), s.map(state), now); }
                    Op::Advance(ms) => now += ms as i64,
                    Op::Tick => { l.tick(now); }
                    Op::Close(n) => l.closed(pick(&epochs, n), now),
                    Op::Send(t) => {
                        let t = t as usize;
                        if stored[t] { continue; }
                        let id = format!("t{t}");
                        let blocked = l.blocked(now);
                        if let Some(e) = l.send(&id, now) {
                            prop_assert!(blocked.is_none(), "sent while {blocked:?}");
                            let s = l.session.as_ref().unwrap();
                            prop_assert!(s.state.armed() && s.epoch == e);
                            prop_assert!(l.quarantine.is_none());
                            last_sent[t] = Some(e);
                        }
                    }
                    Op::Result(t, n) => {
                        let t = t as usize;
                        let e = pick(&epochs, n);
                        let id = format!("t{t}");
                        if l.check_result(e, &id).is_ok() {
                            prop_assert!(!stored[t], "t{t} taken twice");
                            prop_assert_eq!(last_sent[t], Some(e), "taken under an epoch it was not last sent with");
                            stored[t] = true;
                            l.done(&id);
                        }
                    }
                    Op::Refused(t, n) => l.refused(pick(&epochs, n), &format!("t{t}"), now),
                    Op::Quarantine(q) => l.quarantine = q.then(|| "q".to_string()),
                }
                // One trial out at a time, under the epoch it was last sent with.
                if let Some(o) = &l.outstanding {
                    if let Some(e) = o.sent_epoch {
                        let t: usize = o.trial_id[1..].parse().unwrap();
                        prop_assert_eq!(last_sent[t], Some(e));
                    }
                }
            }
        }
    }

    fn timing() -> Timing {
        Timing {
            heartbeat_ms: 100,
            ttl_ms: 500,
            grace_ms: 500,
        }
    }

    #[test]
    fn a_message_keeps_only_its_own_session_alive() {
        // Opened at 10 s (a clock far from 0, so a sum is not a difference).
        let mut l = Lease::new(timing());
        l.open(5, "a", "b", RigState::Disarmed, 10_000).unwrap();
        assert!(!l.heard(4, Some(RigState::Armed), 10_400), "a stale epoch");
        assert!(!l.connected(10_501), "still silent since 10 000");
        assert_eq!(l.session.as_ref().unwrap().state, RigState::Disarmed);
        assert!(l.heard(5, Some(RigState::Armed), 10_400));
        assert!(l.session.as_ref().unwrap().state.armed());
        assert!(l.connected(10_900) && !l.connected(10_901));
        // Lost from 10 901 (since 10 900), fenced after 11 400.
        assert_eq!(l.tick(10_900), None);
        assert_eq!(l.lost_since_ms, None);
        assert_eq!(l.tick(10_901), None);
        assert_eq!(l.lost_since_ms, Some(10_900));
        assert_eq!(l.tick(11_400), None);
        assert!(l.session.is_some());
        assert_eq!(l.tick(11_401), Some(5));
        assert!(l.session.is_none());
    }

    #[test]
    fn a_reconnect_keeps_the_trial_the_agent_runs_and_sends_again_the_one_it_lost() {
        let mut l = Lease::new(timing());
        l.open(1, "a", "b", RigState::Armed, 0).unwrap();
        assert_eq!(l.send("t", 0), Some(1));
        l.closed(2, 100);
        assert!(l.session.is_some(), "another epoch's close changes nothing");
        l.closed(1, 100);
        assert!(l.session.is_none());
        assert_eq!(l.check_result(1, "t"), Ok(()), "still out under epoch 1");
        // The agent comes back running it: it stays out under epoch 1.
        l.open(2, "a", "b", RigState::Armed, 200).unwrap();
        l.resume(Some("t"));
        assert_eq!(l.check_result(1, "t"), Ok(()));
        assert_eq!(l.send("t", 200), None, "not sent twice");
        // It comes back (killed meanwhile) running nothing: sent again.
        l.closed(2, 300);
        l.open(3, "a", "c", RigState::Armed, 400).unwrap();
        l.resume(None);
        assert_eq!(
            l.check_result(1, "t"),
            Err(Refusal::StaleEpoch { sent: None })
        );
        assert_eq!(l.send("t", 400), Some(3));
    }

    #[test]
    fn a_closed_links_trial_is_fenced_after_ttl_and_grace() {
        // Closed at 2 s: its trial is still taken under its epoch until
        // TTL + grace (1 s) have passed, then fenced.
        let mut l = Lease::new(timing());
        l.open(1, "a", "b", RigState::Armed, 1_000).unwrap();
        assert_eq!(l.send("t", 1_000), Some(1));
        l.closed(1, 2_000);
        assert_eq!(l.closed_ms, Some(2_000));
        assert_eq!(l.tick(3_000), None);
        assert_eq!(l.check_result(1, "t"), Ok(()));
        assert_eq!(l.tick(3_001), None);
        assert_eq!(
            l.check_result(1, "t"),
            Err(Refusal::StaleEpoch { sent: None })
        );
        assert_eq!(l.closed_ms, None);
    }

    #[test]
    fn one_trial_is_out_at_a_time_and_one_not_yet_out_gives_way() {
        let mut l = Lease::new(timing());
        l.open(1, "a", "b", RigState::Armed, 0).unwrap();
        assert_eq!(l.send("a", 0), Some(1));
        // A refusal of another trial, or of a under another epoch, leaves a out.
        l.refused(1, "b", 0);
        l.refused(7, "a", 0);
        assert_eq!(l.check_result(1, "a"), Ok(()));
        assert_eq!(l.send("b", 0), None, "a is out: b waits");
        assert_eq!(l.check_result(1, "b"), Err(Refusal::NotSent));
        l.done("b");
        assert_eq!(l.check_result(1, "a"), Ok(()), "done(b) leaves a out");
        l.done("a");
        assert_eq!(l.send("b", 0), Some(1));
        l.done("b");
        // Quarantined: c waits unsent; a search that asks for d instead
        // (c's was cancelled) replaces it, and d goes once released.
        l.quarantine = Some("q".into());
        assert_eq!(l.send("c", 0), None);
        assert_eq!(l.send("d", 0), None);
        assert_eq!(l.outstanding.as_ref().unwrap().trial_id, "d");
        l.quarantine = None;
        assert_eq!(l.send("d", 0), Some(1));
        assert_eq!(l.check_result(1, "c"), Err(Refusal::NotSent));
    }

    #[test]
    fn refusals_say_which_epoch_and_why() {
        // The texts the audit and tests/it/agents.rs look for.
        assert_eq!(
            Refusal::NotSent.describe(3),
            "a result for a trial that is not out"
        );
        assert_eq!(
            Refusal::StaleEpoch { sent: Some(4) }.describe(2),
            "stale epoch 2: the trial is out under epoch 4"
        );
        assert_eq!(
            Refusal::StaleEpoch { sent: None }.describe(1),
            "stale epoch 1: the trial was fenced off and waits to be sent again"
        );
    }

    #[test]
    fn silence_loses_contact_after_the_ttl_and_fences_after_the_grace() {
        // TTL 500 ms, grace 500 ms (the figures given): heard at 0, lost
        // from 501, fenced (epoch ended, trial to be sent again) from 1001.
        let mut l = Lease::new(Timing {
            heartbeat_ms: 100,
            ttl_ms: 500,
            grace_ms: 500,
        });
        l.open(1, "a", "b", RigState::Armed, 0).unwrap();
        assert_eq!(l.send("t", 0), Some(1));
        assert_eq!(l.tick(500), None);
        assert!(l.connected(500) && !l.connected(501));
        assert_eq!(l.tick(501), None);
        assert_eq!(l.lost_since_ms, Some(500));
        assert!(l.blocked(501).unwrap().contains("lost contact"));
        assert_eq!(l.tick(1000), None, "still within the grace");
        assert_eq!(l.check_result(1, "t"), Ok(()), "its result still counts");
        assert_eq!(l.tick(1001), Some(1));
        assert!(l.session.is_none());
        assert_eq!(
            l.check_result(1, "t"),
            Err(Refusal::StaleEpoch { sent: None })
        );
        // A second agent is refused while the first is heard …
        l.open(2, "a", "b", RigState::Armed, 2000).unwrap();
        assert!(l.open(3, "other", "c", RigState::Armed, 2400).is_err());
        // … and takes over once it is silent past the TTL; an old epoch never.
        assert!(l.open(2, "x", "y", RigState::Armed, 9000).is_err());
        l.open(4, "other", "c", RigState::Armed, 2501).unwrap();
        assert_eq!(l.send("t", 2501), Some(4));
        assert_eq!(
            l.check_result(2, "t"),
            Err(Refusal::StaleEpoch { sent: Some(4) })
        );
        // Refused (the agent busy): asked again one heartbeat later, not at once.
        l.refused(4, "t", 2600);
        assert_eq!(l.send("t", 2699), None);
        assert_eq!(l.send("t", 2700), Some(4));
    }
}
