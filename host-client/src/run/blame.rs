//! Whose failure a guest that stops answering is, decided by what the agent did
//! (docs/compatibility.md, "Blame after an agent's action").
//!
//! Upstream has no rule: any exception in a task leaves it without a result, so
//! an agent whose code ends, hangs or reboots the guest takes the task out of the
//! success rate's denominator and gets it retried. Here the step decides:
//!
//! - The guest answered at the step's start (its observation was taken) and
//!   again right before the step's first action ran ([`before_actions`]). If it
//!   fails that second question, it failed while the agent was deciding: the
//!   environment's failure, the task unfinished and retried.
//! - Once an action of the step has run (code, input, a clipboard write), a guest
//!   that stops answering, in the action itself, in the observation after it, or
//!   in a later action of the step, failed because of the agent
//!   ([`after_action`]): the task is finished with score 0, "Failed by: agent",
//!   and is not retried.
//!
//! - And from then on for the rest of the episode: once an action of the agent
//!   has reached the guest, a guest that stops answering or restarts later (while
//!   the agent decides a later step, in the postconfig, in the evaluation) is the
//!   agent's failure too, so a kill or reboot it schedules to land later cannot
//!   turn its task into an unfinished one. A restart shows as another boot id in
//!   `/v1/health` ([`restarted`]) even when the guest answers.
//!
//! - Unless the harness knows the environment failed on its own: a VM whose
//!   QEMU was killed, crashed or was told to quit by the host ([`GuestWatch`])
//!   is the environment's failure at any point of the episode. A guest that shut
//!   itself down (QMP's `SHUTDOWN` with `guest-shutdown`) or reset itself is not
//!   an outside cause.
//!
//! It is not the pool: the pool only reads the status (an agent error is never
//! retried) and asks the guest for its health afterwards to set a dead one aside.

use std::time::Duration;

use arena_exec::AgentAction;
use arena_results::EpisodeStatus;

/// Longest the question "does the guest still answer?" before a step's actions
/// may take: a hung guest costs this much, then the step is the environment's.
pub const DECIDING_CHECK: Duration = Duration::from_secs(10);

/// Where in a step the guest stopped answering.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Before any action of the step ran: the agent was deciding.
    Deciding,
    /// After at least one action of the step ran.
    Acting,
}

/// What the harness knows of a guest's surroundings (a VM fleet knows its QEMUs).
#[async_trait::async_trait]
pub trait GuestWatch: Send + Sync {
    /// Why the guest at `guest` (its URL) stopped answering for a reason outside
    /// it, when it did; `None` when nothing outside the guest failed.
    async fn outside_failure(&self, guest: &str) -> Option<String>;
}

impl std::fmt::Debug for dyn GuestWatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GuestWatch")
    }
}

/// [`after_action`], unless `watch` knows the guest's environment failed on its
/// own: then the environment's failure, unfinished and retried.
pub async fn after_action_unless_outside(
    watch: Option<&dyn GuestWatch>,
    guest: &str,
    step: u32,
    what: &str,
    err: impl std::fmt::Display,
) -> EpisodeStatus {
    if let Some(why) = match watch {
        Some(watch) => watch.outside_failure(guest).await,
        None => None,
    } {
        return EpisodeStatus::InfraError(format!(
            "the guest stopped answering in step {step} ({what}): {err}; {why}, which no action of the agent does, so the failure is the environment's"
        ));
    }
    after_action(step, what, err)
}

/// Whether `action` reaches the guest (anything but the decisions DONE, FAIL
/// and WAIT, which run nothing).
pub fn reaches_guest(action: &AgentAction) -> bool {
    !matches!(action, AgentAction::Done | AgentAction::Fail | AgentAction::Wait)
}

/// Whether the guest must be asked for its health before the step's actions:
/// only when one of them reaches the guest.
pub fn before_actions(actions: &[AgentAction]) -> bool {
    actions.iter().any(reaches_guest)
}

/// The status of an episode whose guest stopped answering in `phase` of `step`
/// (`what` says where, `err` how).
pub fn guest_failure(phase: Phase, step: u32, what: &str, err: impl std::fmt::Display) -> EpisodeStatus {
    match phase {
        Phase::Deciding => EpisodeStatus::InfraError(format!(
            "the guest stopped answering while the agent was deciding step {step} ({what}): {err}"
        )),
        Phase::Acting => after_action(step, what, err),
    }
}

/// The agent's failure: the guest stopped answering after an action of the agent ran.
pub fn after_action(step: u32, what: &str, err: impl std::fmt::Display) -> EpisodeStatus {
    EpisodeStatus::AgentError(format!(
        "{AFTER_ACTION} {step} ({what}): {err}; it answered before the action, so the failure is the agent's"
    ))
}

/// The words that open [`after_action`]'s message, which the pool and reports look for.
pub const AFTER_ACTION: &str = "the guest stopped answering after the agent's action in step";

/// Why the guest is another one than before, when its boot id changed from
/// `before` to `now`; `None` when either is unknown (an older guest) or they match.
pub fn restarted(before: Option<&str>, now: Option<&str>) -> Option<String> {
    match (before, now) {
        (Some(before), Some(now)) if before != now => {
            Some(format!("the guest restarted (its boot id was {before} and is now {now})"))
        }
        _ => None,
    }
}

/// Whether `status` is [`after_action`]'s: the guest is likely gone.
pub fn guest_lost_by_agent(status: &EpisodeStatus) -> bool {
    matches!(status, EpisodeStatus::AgentError(m) if m.starts_with(AFTER_ACTION))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_while_deciding_is_the_environments_and_after_an_action_the_agents() {
        let deciding = guest_failure(Phase::Deciding, 3, "before the actions", "refused");
        assert!(deciding.is_infra() && deciding.is_unfinished(), "{deciding:?}");
        let acting = guest_failure(Phase::Acting, 3, "the action", "reset");
        assert!(!acting.is_unfinished(), "{acting:?}");
        assert!(guest_lost_by_agent(&acting));
        assert!(!guest_lost_by_agent(&deciding));
        assert!(!guest_lost_by_agent(&EpisodeStatus::AgentError("the plan is used up".into())));
        assert_eq!(arena_results::Blame::of(&acting, 0.0).name(), "agent");
    }

    struct Watch(Option<&'static str>);

    #[async_trait::async_trait]
    impl GuestWatch for Watch {
        async fn outside_failure(&self, guest: &str) -> Option<String> {
            assert_eq!(guest, "http://vm-1");
            self.0.map(str::to_owned)
        }
    }

    #[tokio::test]
    async fn a_guest_whose_vm_was_killed_is_the_environments_failure_even_after_an_action() {
        let killed = Watch(Some("QEMU ended (signal: 9 (SIGKILL))"));
        let status = after_action_unless_outside(Some(&killed), "http://vm-1", 2, "action 1", "reset").await;
        assert!(status.is_infra() && status.is_unfinished(), "{status:?}");
        assert!(status.message().unwrap_or_default().contains("SIGKILL"), "{status:?}");
        let alive = Watch(None);
        let status = after_action_unless_outside(Some(&alive), "http://vm-1", 2, "action 1", "reset").await;
        assert!(guest_lost_by_agent(&status), "{status:?}");
        let status = after_action_unless_outside(None, "http://vm-1", 2, "action 1", "reset").await;
        assert!(guest_lost_by_agent(&status), "{status:?}");
    }

    #[test]
    fn a_changed_boot_id_is_a_restart_and_an_unknown_one_is_not() {
        assert!(restarted(Some("a1"), Some("b2")).is_some_and(|w| w.contains("a1") && w.contains("b2")));
        assert_eq!(restarted(Some("a1"), Some("a1")), None);
        assert_eq!(restarted(None, Some("a1")), None);
        assert_eq!(restarted(Some("a1"), None), None);
    }

    #[test]
    fn only_actions_that_reach_the_guest_call_for_the_check() {
        assert!(!before_actions(&[AgentAction::Wait, AgentAction::Done]));
        assert!(!before_actions(&[]));
        assert!(before_actions(&[AgentAction::Fail, AgentAction::Pyautogui("pyautogui.click(1, 1)".into())]));
    }
}
