//! Whether the desktop has settled after a boot: the `shell` health component.
//!
//! A freshly logged-on Windows keeps starting things for a while after the
//! guest answers: Explorer builds the taskbar, start-up apps open windows,
//! Defender and the Store work in the background. A snapshot saved then hands
//! every task a desktop that is still moving. The shell counts as settled when
//! the taskbar is shown, the desktop or the taskbar is in front (no start-up
//! window over it), and the CPU has stayed under [`BUSY_PERCENT_MAX`] busy for
//! the configured idle time (`--settle-idle-ms`).
//!
//! Neutral and tested everywhere: the backends hand in a [`ShellSample`] (the
//! Windows one from `Shell_TrayWnd`, the foreground window's class and
//! `GetSystemTimes`; the stub from its model of a shell that settles late), and
//! [`Settle`] keeps the CPU's history between health probes.

use std::time::{Duration, Instant};

/// A CPU busier than this, in percent of all processors' time between two
/// samples, is not idle.
pub const BUSY_PERCENT_MAX: u64 = 15;

/// What is in front of the desktop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Front {
    /// The desktop itself (Windows: `Progman` or `WorkerW`), or nothing at all.
    Desktop,
    /// The taskbar (`Shell_TrayWnd`).
    Taskbar,
    /// Another window, by its title (or class when it has none).
    Window(String),
}

impl Front {
    /// The foreground window by its class and title (Windows: `GetForegroundWindow`,
    /// `GetClassNameW`, `GetWindowTextW`; `None` when no window has the foreground).
    /// The desktop is Explorer's `Progman` window, or the `WorkerW` it puts behind
    /// the icons; the taskbar is `Shell_TrayWnd` (or a second screen's
    /// `Shell_SecondaryTrayWnd`).
    pub fn of_window(window: Option<(&str, &str)>) -> Front {
        match window {
            None | Some(("Progman" | "WorkerW", _)) => Front::Desktop,
            Some(("Shell_TrayWnd" | "Shell_SecondaryTrayWnd", _)) => Front::Taskbar,
            Some((class, "")) => Front::Window(class.to_owned()),
            Some((_, title)) => Front::Window(title.to_owned()),
        }
    }
}

/// All processors' time since boot, in any one unit (Windows: 100 ns ticks of
/// `GetSystemTimes`, whose kernel time includes the idle time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CpuTimes {
    pub idle: u64,
    pub total: u64,
}

/// One look at the shell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShellSample {
    /// The taskbar window exists and is visible.
    pub taskbar: bool,
    pub front: Front,
    /// `None` where the CPU's times cannot be read.
    pub cpu: Option<CpuTimes>,
}

/// The CPU's history between probes and the rule over it.
#[derive(Debug)]
pub struct Settle {
    idle_for: Duration,
    last: Option<(Instant, CpuTimes)>,
    /// Since when every interval between samples was idle.
    idle_since: Option<Instant>,
    /// The last interval's busy share, in percent.
    last_busy: Option<u64>,
}

impl Settle {
    /// A rule that wants the CPU idle for `idle_for` (zero: the CPU is not consulted).
    pub fn new(idle_for: Duration) -> Settle {
        Settle { idle_for, last: None, idle_since: None, last_busy: None }
    }

    /// Takes `sample`, seen at `now`, into the history and says whether the
    /// shell has settled, and why not.
    ///
    /// # Errors
    ///
    /// What is not settled yet, every reason at once.
    pub fn judge(&mut self, now: Instant, sample: &ShellSample) -> Result<String, String> {
        if let Some(cpu) = sample.cpu {
            if let Some((then, before)) = self.last {
                if cpu.total > before.total && cpu.idle >= before.idle {
                    let total = cpu.total - before.total;
                    let idle = (cpu.idle - before.idle).min(total);
                    let busy = (total - idle).saturating_mul(100) / total;
                    self.last_busy = Some(busy);
                    if busy > BUSY_PERCENT_MAX {
                        self.idle_since = None;
                    } else if self.idle_since.is_none() {
                        self.idle_since = Some(then);
                    }
                } else if cpu.total < before.total {
                    // A counter that went back (a restored snapshot's): measure from here.
                    self.idle_since = None;
                    self.last_busy = None;
                }
            }
            self.last = Some((now, cpu));
        }
        let mut waiting = Vec::new();
        if !sample.taskbar {
            waiting.push("the taskbar is not shown yet".to_owned());
        }
        if let Front::Window(title) = &sample.front {
            waiting.push(format!("a window is in front of the desktop: {title:?}"));
        }
        let idle = self.idle_since.map(|since| now.saturating_duration_since(since));
        if !self.idle_for.is_zero() {
            match (sample.cpu, self.last_busy, idle) {
                (None, _, _) => waiting.push("the CPU's times cannot be read".to_owned()),
                (Some(_), None, _) => waiting.push("measuring the CPU (one sample so far)".to_owned()),
                (Some(_), Some(busy), None) => {
                    waiting.push(format!("the CPU is busy ({busy}% since the last look, over {BUSY_PERCENT_MAX}%)"))
                }
                (Some(_), Some(_), Some(idle)) if idle < self.idle_for => waiting.push(format!(
                    "the CPU has been idle for {:.1} s of the {:.1} s wanted",
                    idle.as_secs_f64(),
                    self.idle_for.as_secs_f64()
                )),
                _ => {}
            }
        }
        if !waiting.is_empty() {
            return Err(format!("the desktop is still settling: {}", waiting.join("; ")));
        }
        let front = match sample.front {
            Front::Taskbar => "the taskbar",
            _ => "the desktop",
        };
        Ok(match idle {
            Some(idle) if !self.idle_for.is_zero() => format!(
                "settled: taskbar shown, {front} in front, CPU idle (at most {BUSY_PERCENT_MAX}% busy) for {:.1} s",
                idle.as_secs_f64()
            ),
            _ => format!("settled: taskbar shown, {front} in front (the CPU is not consulted)"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(taskbar: bool, front: Front, idle: u64, total: u64) -> ShellSample {
        ShellSample { taskbar, front, cpu: Some(CpuTimes { idle, total }) }
    }

    #[test]
    fn the_shell_settles_once_shown_in_front_and_idle_long_enough() {
        let t0 = Instant::now();
        let at = |s: u64| t0 + Duration::from_secs(s);
        let mut settle = Settle::new(Duration::from_secs(5));
        // Nothing measured yet, and no taskbar: both said.
        let err = settle.judge(at(0), &sample(false, Front::Desktop, 0, 0)).unwrap_err();
        assert!(err.contains("taskbar is not shown") && err.contains("one sample so far"), "{err}");
        // Busy: 60% of the interval.
        let err = settle.judge(at(2), &sample(true, Front::Desktop, 40, 100)).unwrap_err();
        assert!(err.contains("busy (60%"), "{err}");
        // Idle from second 2 on, but only 2 s of the 5 wanted.
        let err = settle.judge(at(4), &sample(true, Front::Desktop, 135, 200)).unwrap_err();
        assert!(err.contains("idle for 2.0 s of the 5.0 s"), "{err}");
        // A start-up window in front holds it even with an idle CPU.
        let err = settle.judge(at(7), &sample(true, Front::Window("OneDrive".into()), 330, 400)).unwrap_err();
        assert!(err.contains("\"OneDrive\"") && !err.contains("CPU"), "{err}");
        let ok = settle.judge(at(8), &sample(true, Front::Taskbar, 428, 500)).unwrap();
        assert!(ok.contains("the taskbar in front") && ok.contains("for 6.0 s"), "{ok}");
        // A burst starts the idle time over.
        assert!(settle.judge(at(9), &sample(true, Front::Desktop, 450, 600)).is_err());
        assert!(settle.judge(at(10), &sample(true, Front::Desktop, 550, 700)).is_err());
    }

    #[test]
    fn the_foreground_is_read_by_its_class() {
        assert_eq!(Front::of_window(None), Front::Desktop);
        assert_eq!(Front::of_window(Some(("Progman", "Program Manager"))), Front::Desktop);
        assert_eq!(Front::of_window(Some(("WorkerW", ""))), Front::Desktop);
        assert_eq!(Front::of_window(Some(("Shell_TrayWnd", ""))), Front::Taskbar);
        assert_eq!(
            Front::of_window(Some(("Notepad", "Untitled - Notepad"))),
            Front::Window("Untitled - Notepad".into())
        );
        assert_eq!(Front::of_window(Some(("OneDriveWnd", ""))), Front::Window("OneDriveWnd".into()));
    }

    #[test]
    fn without_an_idle_time_or_cpu_times() {
        let now = Instant::now();
        let mut quick = Settle::new(Duration::ZERO);
        let ok = quick.judge(now, &ShellSample { taskbar: true, front: Front::Desktop, cpu: None }).unwrap();
        assert!(ok.contains("not consulted"), "{ok}");
        let mut careful = Settle::new(Duration::from_secs(1));
        let err = careful.judge(now, &ShellSample { taskbar: true, front: Front::Desktop, cpu: None }).unwrap_err();
        assert!(err.contains("cannot be read"), "{err}");
        // A counter that goes back (a restored snapshot) starts the measure over.
        careful.judge(now, &sample(true, Front::Desktop, 0, 0)).unwrap_err();
        careful.judge(now + Duration::from_secs(2), &sample(true, Front::Desktop, 100, 100)).unwrap();
        let err = careful.judge(now + Duration::from_secs(3), &sample(true, Front::Desktop, 10, 10)).unwrap_err();
        assert!(err.contains("measuring the CPU"), "{err}");
    }
}
