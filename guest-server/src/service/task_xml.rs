//! The logon task's definition as Task Scheduler XML, which `schtasks /Create /XML`
//! registers (`logon-task install`).
//!
//! Why XML and not `schtasks /Create /SC ONLOGON /TR ...`: the command-line form
//! cannot set the settings the server needs. A task it creates is stopped after
//! Task Scheduler's default 72 hours (`ExecutionTimeLimit` `PT72H`) and runs at the
//! default priority 7, which is below normal (and lowers the process's I/O and memory
//! priority too). The XML here sets no time limit (`PT0S`) and priority
//! [`NORMAL_PRIORITY`]. It also keeps the command line out of `/TR`'s 261-character
//! limit, and it is the one creation form Wine 8's `schtasks.exe` supports.
//!
//! The task starts `arena-guest-logon.exe SERVE OPTIONS` ([`arena_guest_launch::exes::LAUNCHER_EXE`])
//! in the installing user's session, with their highest privileges, in the exes'
//! folder. That launcher is a GUI-subsystem program, so Task Scheduler's start of it
//! opens no console window, and it starts the server (`arena-guest.exe`, a console
//! program) with `CREATE_NO_WINDOW` (see the `windows` half of [`crate::service`]).
//!
//! Platform-neutral and tested natively; the glue writes the file and runs `schtasks`.

use std::fmt::Write as _;
use std::path::Path;

use arena_shared::markup::escape;

/// Task Scheduler's `Priority` for a normal process (`NORMAL_PRIORITY_CLASS`): 4 to 6
/// are normal, 7 (the default) and 8 below normal, 0 to 3 above.
pub const NORMAL_PRIORITY: u8 = 4;

/// The time limit that means "none" in the task schema's duration type.
pub const NO_TIME_LIMIT: &str = "PT0S";

/// What goes into the logon task.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogonTask<'a> {
    /// `DOMAIN\name` of the user whose logon starts the task and who runs it; `None`
    /// leaves both to Task Scheduler (the registering user, at any user's logon).
    pub user: Option<&'a str>,
    /// The program the task runs (not quoted: the schema holds the path as it is).
    pub command: &'a Path,
    /// Its arguments, already joined into one command-line string.
    pub arguments: &'a str,
    /// Its working directory.
    pub working_dir: Option<&'a Path>,
}

/// The task definition (schema 1.2, Windows 7 and later): a logon trigger; the user's
/// interactive token at their highest run level (an administrator's full token, as
/// upstream's `/RL HIGHEST` task); no time limit; normal priority; one instance; no
/// conditions on power, idleness or network; visible in Task Scheduler's library.
///
/// The XML declares UTF-16, the encoding [`to_utf16_file`] writes.
pub fn logon_task_xml(task: &LogonTask<'_>) -> String {
    let user = task.user.map(|user| format!("      <UserId>{}</UserId>\n", escape(user))).unwrap_or_default();
    let mut xml = String::new();
    xml.push_str("<?xml version=\"1.0\" encoding=\"UTF-16\"?>\n");
    xml.push_str("<Task version=\"1.2\" xmlns=\"http://schemas.microsoft.com/windows/2004/02/mit/task\">\n");
    xml.push_str("  <RegistrationInfo>\n");
    xml.push_str(
        "    <Description>Starts arena-guest, the desktop-control server, at logon without a console window.\
         </Description>\n",
    );
    xml.push_str("  </RegistrationInfo>\n");
    xml.push_str("  <Triggers>\n    <LogonTrigger>\n      <Enabled>true</Enabled>\n");
    xml.push_str(&user);
    xml.push_str("    </LogonTrigger>\n  </Triggers>\n");
    xml.push_str("  <Principals>\n    <Principal id=\"Author\">\n");
    xml.push_str(&user);
    xml.push_str("      <LogonType>InteractiveToken</LogonType>\n");
    xml.push_str("      <RunLevel>HighestAvailable</RunLevel>\n");
    xml.push_str("    </Principal>\n  </Principals>\n");
    xml.push_str("  <Settings>\n");
    for (name, value) in [
        ("MultipleInstancesPolicy", "IgnoreNew"),
        ("DisallowStartIfOnBatteries", "false"),
        ("StopIfGoingOnBatteries", "false"),
        ("AllowHardTerminate", "true"),
        ("StartWhenAvailable", "false"),
        ("RunOnlyIfNetworkAvailable", "false"),
    ] {
        let _ = writeln!(xml, "    <{name}>{value}</{name}>");
    }
    xml.push_str("    <IdleSettings>\n      <StopOnIdleEnd>false</StopOnIdleEnd>\n");
    xml.push_str("      <RestartOnIdle>false</RestartOnIdle>\n    </IdleSettings>\n");
    for (name, value) in [
        ("AllowStartOnDemand", "true"),
        ("Enabled", "true"),
        ("Hidden", "false"),
        ("RunOnlyIfIdle", "false"),
        ("ExecutionTimeLimit", NO_TIME_LIMIT),
    ] {
        let _ = writeln!(xml, "    <{name}>{value}</{name}>");
    }
    let _ = writeln!(xml, "    <Priority>{NORMAL_PRIORITY}</Priority>");
    xml.push_str("  </Settings>\n");
    xml.push_str("  <Actions Context=\"Author\">\n    <Exec>\n");
    let _ = writeln!(xml, "      <Command>{}</Command>", escape(&task.command.display().to_string()));
    if !task.arguments.is_empty() {
        let _ = writeln!(xml, "      <Arguments>{}</Arguments>", escape(task.arguments));
    }
    if let Some(dir) = task.working_dir {
        let _ = writeln!(xml, "      <WorkingDirectory>{}</WorkingDirectory>", escape(&dir.display().to_string()));
    }
    xml.push_str("    </Exec>\n  </Actions>\n</Task>\n");
    xml
}

/// `xml` as the bytes of a file `schtasks /XML` reads: UTF-16 little-endian with a
/// byte-order mark (both Windows' and Wine's `schtasks` take that).
pub fn to_utf16_file(xml: &str) -> Vec<u8> {
    let mut bytes = vec![0xFF, 0xFE];
    for unit in xml.encode_utf16() {
        bytes.extend_from_slice(&unit.to_le_bytes());
    }
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> String {
        logon_task_xml(&LogonTask {
            user: Some(r"ARENA-VM\Docker"),
            command: Path::new(r"C:\Program Files\Arena\arena-guest-logon.exe"),
            arguments: r#"--port 5000 --token-file "C:\Program Files\Arena\t&k""#,
            working_dir: Some(Path::new(r"C:\Program Files\Arena")),
        })
    }

    /// The text of the one `<name>` element inside `<parent>`.
    fn element<'a>(xml: &'a str, parent: &str, name: &str) -> &'a str {
        let start = xml.find(&format!("<{parent}")).unwrap_or_else(|| panic!("no <{parent}> in\n{xml}"));
        let end = xml[start..].find(&format!("</{parent}>")).unwrap() + start;
        let scope = &xml[start..end];
        let open = format!("<{name}>");
        let from = scope.find(&open).unwrap_or_else(|| panic!("no <{name}> in <{parent}>")) + open.len();
        let to = scope[from..].find(&format!("</{name}>")).unwrap() + from;
        assert_eq!(scope.matches(&open).count(), 1, "<{name}> appears once in <{parent}>");
        &scope[from..to]
    }

    #[test]
    fn the_task_has_no_time_limit_and_normal_priority() {
        let xml = sample();
        assert_eq!(element(&xml, "Settings", "ExecutionTimeLimit"), "PT0S");
        assert_eq!(element(&xml, "Settings", "Priority"), "4");
        // Below normal (7) is Task Scheduler's default and what schtasks /SC gives.
        assert!(!xml.contains("<Priority>7</Priority>"));
        assert_eq!(element(&xml, "Settings", "MultipleInstancesPolicy"), "IgnoreNew");
        assert_eq!(element(&xml, "Settings", "DisallowStartIfOnBatteries"), "false");
        assert_eq!(element(&xml, "Settings", "StopIfGoingOnBatteries"), "false");
        assert_eq!(element(&xml, "IdleSettings", "StopOnIdleEnd"), "false");
        assert_eq!(element(&xml, "Settings", "RunOnlyIfIdle"), "false");
    }

    #[test]
    fn it_starts_at_the_users_logon_in_their_session_with_their_highest_rights() {
        let xml = sample();
        assert!(xml.contains("<Triggers>\n    <LogonTrigger>"), "{xml}");
        assert_eq!(element(&xml, "LogonTrigger", "Enabled"), "true");
        assert_eq!(element(&xml, "LogonTrigger", "UserId"), r"ARENA-VM\Docker");
        assert_eq!(element(&xml, "Principal", "UserId"), r"ARENA-VM\Docker");
        // The user's own desktop session (not "whether logged on or not", which has no desktop).
        assert_eq!(element(&xml, "Principal", "LogonType"), "InteractiveToken");
        assert_eq!(element(&xml, "Principal", "RunLevel"), "HighestAvailable");
        // `Hidden` only hides the task in Task Scheduler's library; the window is the launcher's business.
        assert_eq!(element(&xml, "Settings", "Hidden"), "false");

        let anyone = logon_task_xml(&bare_task());
        assert!(!anyone.contains("<UserId>"), "{anyone}");
    }

    fn bare_task() -> LogonTask<'static> {
        LogonTask { user: None, command: Path::new(r"C:\a\arena-guest-logon.exe"), arguments: "", working_dir: None }
    }

    #[test]
    fn the_action_runs_the_launcher_in_the_exes_folder_with_text_escaped() {
        let xml = sample();
        assert_eq!(element(&xml, "Exec", "Command"), r"C:\Program Files\Arena\arena-guest-logon.exe");
        assert_eq!(
            element(&xml, "Exec", "Arguments"),
            r#"--port 5000 --token-file &quot;C:\Program Files\Arena\t&amp;k&quot;"#
        );
        // One action: the launcher alone, never arena-guest.exe (a console program) itself.
        assert_eq!(xml.matches("<Exec>").count(), 1);
        assert_eq!(element(&xml, "Exec", "WorkingDirectory"), r"C:\Program Files\Arena");
        let bare = logon_task_xml(&bare_task());
        assert!(!bare.contains("<Arguments>") && !bare.contains("<WorkingDirectory>"), "{bare}");
        assert_eq!(escape("<a & 'b'>"), "&lt;a &amp; &#39;b&#39;&gt;");
    }

    #[test]
    fn the_file_is_utf16_with_a_byte_order_mark_as_declared() {
        let xml = sample();
        assert!(xml.starts_with("<?xml version=\"1.0\" encoding=\"UTF-16\"?>"));
        let bytes = to_utf16_file("<é>");
        assert_eq!(bytes, [0xFF, 0xFE, b'<', 0, 0xE9, 0, b'>', 0]);
        let units: Vec<u16> =
            to_utf16_file(&xml)[2..].chunks_exact(2).map(|pair| u16::from_le_bytes([pair[0], pair[1]])).collect();
        assert_eq!(String::from_utf16(&units).unwrap(), xml);
    }
}
