//! Which windows a reset closes: the one rule behind the guest's `/setup/close_all`
//! and the host's reset between episodes.
//!
//! Upstream closes every visible window with a title except the desktop (`Program
//! Manager`) and the elevated PowerShell console its own server runs in. This
//! server has no console, but must never close its own windows either (it may have
//! some, e.g. under Wine or in logon-task mode), which the guest knows by process id
//! and the host by the executable's name.

use crate::observation::WindowInfo;

/// Title of the elevated console upstream's scheduled task runs its server in.
pub const ADMIN_POWERSHELL: &str = r"Administrator: C:\Windows\System32\WindowsPowerShell\v1.0\powershell.exe";

/// Title of the desktop window.
pub const DESKTOP_TITLE: &str = "Program Manager";

/// Whether a reset leaves `window` open. `server_pid` is the guest server's process id
/// where the caller knows it (the guest itself); every caller also spares processes
/// whose executable is this guest server's (`arena-guest…`).
pub fn spares(window: &WindowInfo, server_pid: Option<u32>) -> bool {
    let process = window.process_name.to_ascii_lowercase();
    !window.visible
        || window.title.is_empty()
        || window.title == DESKTOP_TITLE
        || window.title == ADMIN_POWERSHELL
        || server_pid.is_some_and(|pid| pid == window.process_id)
        || process.starts_with("arena-guest")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(title: &str, process: &str, pid: u32, visible: bool) -> WindowInfo {
        WindowInfo {
            title: title.to_owned(),
            process_name: process.to_owned(),
            process_id: pid,
            visible,
            ..WindowInfo::default()
        }
    }

    #[test]
    fn spares_the_desktop_the_console_the_server_and_the_hidden() {
        let check = |w: WindowInfo, pid: Option<u32>, spared: bool| {
            assert_eq!(
                spares(&w, pid),
                spared,
                "{:?} {:?} pid {} server {pid:?}",
                w.title,
                w.process_name,
                w.process_id
            );
        };
        check(window("Program Manager", "explorer.exe", 10, true), None, true);
        check(window("", "explorer.exe", 10, true), None, true);
        check(window(ADMIN_POWERSHELL, "powershell.exe", 11, true), None, true);
        check(window("arena", "arena-guest.exe", 12, true), None, true);
        check(window("arena", "Arena-Guest.EXE", 12, true), None, true);
        check(window("Console", "conhost.exe", 13, true), Some(13), true);
        check(window("Console", "conhost.exe", 13, true), Some(14), false);
        check(window("Untitled - Notepad", "notepad.exe", 20, false), None, true);
        check(window("Untitled - Notepad", "notepad.exe", 20, true), None, false);
        check(window("Windows PowerShell", "powershell.exe", 21, true), None, false);
    }
}
