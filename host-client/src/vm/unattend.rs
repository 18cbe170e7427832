//! The answer file (`autounattend.xml`) `arena vm prepare` writes for Windows
//! Setup, from typed options.
//!
//! Every component, pass and setting used here is one Microsoft documents in
//! the "Unattended Windows Setup Reference"
//! (learn.microsoft.com/windows-hardware/customize/desktop/unattend/), with the
//! attributes every amd64 component carries there (`processorArchitecture`,
//! `publicKeyToken="31bf3856ad364e35"`, `language="neutral"`,
//! `versionScope="nonSxS"`). [`DOCUMENTED`] lists them per component and pass,
//! and the tests check the generated file against that list.
//!
//! The file is written whole by this module: no upstream answer file is copied.
//! docs/vm.md compares it, setting by setting, with WAA's and dockur's.
//!
//! What each pass does here:
//! - windowsPE: Setup's language, the disk layout for the firmware (GPT with
//!   EFI, MSR and Windows partitions for UEFI; MBR with an active system
//!   partition for BIOS), the image (by index or by name), the product key when
//!   one is given, the EULA accepted, and, when the VM has no TPM 2.0 or no
//!   Secure Boot, the `LabConfig` keys that let Setup go on without them.
//! - offlineServicing: UAC (`EnableLUA`), off by default as in upstream's images.
//! - specialize: computer name, time zone, `BypassNRO` (a local account without
//!   a network), and the copy of the OEM media to `C:\OEM`.
//! - oobeSystem: no automatic device encryption (each VM has its own TPM),
//!   locale, the local administrator account, auto-logon, OOBE's pages hidden,
//!   and `C:\OEM\install.bat` as the first logon command.

use std::fmt::Write as _;

/// Windows Setup's public key token for every component in the answer file.
pub const PUBLIC_KEY_TOKEN: &str = "31bf3856ad364e35";

/// The file at the root of the OEM media by which the specialize pass finds its
/// drive letter (CD-ROM letters are not fixed).
pub const OEM_MARKER: &str = "ARENA-OEM.TXT";

/// The folder on the OEM media whose contents become `C:\OEM`.
pub const OEM_MEDIA_FOLDER: &str = "OEM";

/// The firmware the answer file lays the disk out for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FirmwareKind {
    /// SeaBIOS: an MBR disk with an active system partition.
    Bios,
    /// OVMF: a GPT disk with an EFI system partition and an MSR.
    Uefi,
}

/// User Account Control in the installed system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Uac {
    /// Off, as in WAA's and dockur's images (the guest and the agent's programs
    /// run at the same integrity level).
    Off,
    /// On (Windows' default): programs the guest starts run elevated.
    On,
}

/// Which image of `install.wim`/`install.esd` Setup applies.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImageChoice {
    /// `/IMAGE/INDEX`: 1 is the only image of an Enterprise evaluation ISO.
    Index(u32),
    /// `/IMAGE/NAME`: the edition's name as the image lists it ("Windows 11 Pro").
    Name(String),
}

/// Everything the answer file is made from.
#[derive(Debug, Clone)]
pub struct AnswerOptions {
    pub image: ImageChoice,
    /// A product key (`XXXXX-XXXXX-XXXXX-XXXXX-XXXXX`), for editions that need one.
    pub product_key: Option<String>,
    pub user: String,
    /// Empty by default, as WAA's `Docker` account.
    pub password: String,
    /// A language tag (`en-US`): Setup's language, system, user and UI locale.
    pub locale: String,
    /// An input locale (`0409:00000409`, or a language tag).
    pub keyboard: String,
    /// A Windows time zone name (`UTC`, `Pacific Standard Time`).
    pub timezone: String,
    /// `*` lets Windows make one up.
    pub computer_name: String,
    pub uac: Uac,
    pub firmware: FirmwareKind,
    /// Write the `LabConfig` keys (no TPM 2.0 or no Secure Boot attached).
    pub bypass_checks: bool,
}

impl AnswerOptions {
    /// The defaults: image 1, user `Docker` with no password (as WAA), en-US,
    /// UTC, UAC off, BIOS with the bypass keys.
    pub fn new() -> AnswerOptions {
        AnswerOptions {
            image: ImageChoice::Index(1),
            product_key: None,
            user: "Docker".into(),
            password: String::new(),
            locale: "en-US".into(),
            keyboard: "0409:00000409".into(),
            timezone: "UTC".into(),
            computer_name: "*".into(),
            uac: Uac::Off,
            firmware: FirmwareKind::Bios,
            bypass_checks: true,
        }
    }

    /// Checks every value against what Windows accepts, so Setup never stops on
    /// a bad one.
    ///
    /// # Errors
    ///
    /// A message naming the option and what is wrong with it.
    pub fn check(&self) -> Result<(), String> {
        match &self.image {
            ImageChoice::Index(0) => return Err("--image-index 0: images are numbered from 1".into()),
            ImageChoice::Name(name) if name.trim().is_empty() => return Err("--edition is empty".into()),
            _ => {}
        }
        if let Some(key) = &self.product_key {
            let groups: Vec<&str> = key.split('-').collect();
            if groups.len() != 5 || groups.iter().any(|g| g.len() != 5 || !g.chars().all(|c| c.is_ascii_alphanumeric()))
            {
                return Err(format!(
                    "--product-key {key:?}: a key is five groups of five letters or digits joined by '-'"
                ));
            }
        }
        // Local account names: at most 20 characters, none of "/\[]:;|=,+*?<> and not only dots or spaces.
        let bad_user = |c: char| "\"/\\[]:;|=,+*?<>@".contains(c) || c.is_control();
        if self.user.is_empty()
            || self.user.chars().count() > 20
            || self.user.chars().any(bad_user)
            || self.user.chars().all(|c| c == '.' || c == ' ')
        {
            return Err(format!(
                "--user {:?}: a Windows local account name has 1 to 20 characters, none of \"/\\[]:;|=,+*?<>@",
                self.user
            ));
        }
        if self.password.chars().any(char::is_control) {
            return Err("--password holds a control character".into());
        }
        if !is_language_tag(&self.locale) {
            return Err(format!("--locale {:?}: use a language tag such as en-US", self.locale));
        }
        if !is_language_tag(&self.keyboard) && !is_input_locale(&self.keyboard) {
            return Err(format!(
                "--keyboard {:?}: use an input locale such as 0409:00000409 or a language tag such as en-US",
                self.keyboard
            ));
        }
        if self.timezone.trim().is_empty()
            || self.timezone.len() > 64
            || !self.timezone.chars().all(|c| c.is_ascii_alphanumeric() || " ()+-._".contains(c))
        {
            return Err(format!("--timezone {:?}: use a Windows time zone name such as UTC", self.timezone));
        }
        let name = &self.computer_name;
        if name != "*"
            && (name.is_empty()
                || name.len() > 15
                || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
                || name.chars().all(|c| c.is_ascii_digit()))
        {
            return Err(format!(
                "--computer-name {name:?}: 1 to 15 letters, digits or '-', not only digits (or * for a generated one)"
            ));
        }
        Ok(())
    }
}

impl Default for AnswerOptions {
    fn default() -> AnswerOptions {
        AnswerOptions::new()
    }
}

fn is_language_tag(text: &str) -> bool {
    let mut parts = text.split('-');
    let Some(first) = parts.next() else { return false };
    (2..=3).contains(&first.len())
        && first.chars().all(|c| c.is_ascii_lowercase())
        && parts.all(|p| (2..=8).contains(&p.len()) && p.chars().all(|c| c.is_ascii_alphanumeric()))
}

fn is_input_locale(text: &str) -> bool {
    text.split(';').all(|one| {
        let Some((lang, layout)) = one.split_once(':') else { return false };
        lang.len() == 4
            && layout.len() == 8
            && lang.chars().all(|c| c.is_ascii_hexdigit())
            && layout.chars().all(|c| c.is_ascii_hexdigit())
    })
}

/// Components documented in the unattend reference, with the passes each
/// setting used here is valid in. Only what this module writes is listed.
pub const DOCUMENTED: &[(&str, &str, &[&str])] = &[
    (
        "Microsoft-Windows-International-Core-WinPE",
        "windowsPE",
        &["SetupUILanguage", "InputLocale", "SystemLocale", "UILanguage", "UserLocale"],
    ),
    (
        "Microsoft-Windows-Setup",
        "windowsPE",
        &["DiskConfiguration", "ImageInstall", "UserData", "RunSynchronous", "DynamicUpdate"],
    ),
    ("Microsoft-Windows-LUA-Settings", "offlineServicing", &["EnableLUA"]),
    ("Microsoft-Windows-Shell-Setup", "specialize", &["ComputerName", "TimeZone"]),
    ("Microsoft-Windows-Deployment", "specialize", &["RunSynchronous"]),
    ("Microsoft-Windows-SecureStartup-FilterDriver", "oobeSystem", &["PreventDeviceEncryption"]),
    (
        "Microsoft-Windows-International-Core",
        "oobeSystem",
        &["InputLocale", "SystemLocale", "UILanguage", "UserLocale"],
    ),
    (
        "Microsoft-Windows-Shell-Setup",
        "oobeSystem",
        &["UserAccounts", "AutoLogon", "OOBE", "FirstLogonCommands", "TimeZone"],
    ),
];

/// The configuration passes in the order Windows Setup runs them.
pub const PASSES: &[&str] =
    &["windowsPE", "offlineServicing", "generalize", "specialize", "auditSystem", "auditUser", "oobeSystem"];

/// The command the specialize pass runs to copy the OEM media's folder to
/// `C:\OEM` (found by its marker file, since CD-ROM drive letters vary).
pub fn oem_copy_command() -> String {
    format!(
        "powershell.exe -NoProfile -ExecutionPolicy Bypass -Command \"$d = Get-PSDrive -PSProvider FileSystem | \
         Where-Object {{ Test-Path -LiteralPath (Join-Path $_.Root '{OEM_MARKER}') }} | Select-Object -First 1; \
         if ($null -eq $d) {{ exit 2 }}; robocopy (Join-Path $d.Root '{OEM_MEDIA_FOLDER}') 'C:\\OEM' /E /R:2 /W:2 /NP /NFL /NDL; \
         if ($LASTEXITCODE -ge 8) {{ exit 1 }}; exit 0\""
    )
}

/// The first logon command: the OEM install (it logs to `%ProgramData%\arena\logs`).
pub const FIRST_LOGON_COMMAND: &str = r"cmd.exe /d /c C:\OEM\install.bat";

/// A command that writes `arena-stage: NAME` to the first serial port, where
/// `arena vm prepare` follows the install's stages (QEMU writes it to `serial.log`).
pub fn stage_command(name: &str) -> String {
    format!("cmd.exe /d /c echo arena-stage: {name}>COM1")
}

/// The `LabConfig` values Windows 11 Setup reads before its hardware checks:
/// only for what the VM lacks without `--firmware uefi` (the TPM and Secure
/// Boot). Memory, disk and processors are given as Setup wants them, so their
/// checks stay on (WAA's and dockur's files also skip the memory check).
pub const LAB_CONFIG: &[&str] = &["BypassTPMCheck", "BypassSecureBootCheck"];

/// `BypassNRO`: OOBE offers a local account without a network.
pub const BYPASS_NRO: &str =
    r#"reg.exe add "HKLM\SOFTWARE\Microsoft\Windows\CurrentVersion\OOBE" /v BypassNRO /t REG_DWORD /d 1 /f"#;

/// The answer file.
pub fn render(o: &AnswerOptions) -> String {
    let mut x = Xml::default();
    x.raw("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    x.raw("<!-- Written by `arena vm prepare`; see docs/vm.md for what each setting does. -->\n");
    x.open_attrs(
        "unattend",
        &[
            ("xmlns", "urn:schemas-microsoft-com:unattend"),
            ("xmlns:wcm", "http://schemas.microsoft.com/WMIConfig/2002/State"),
        ],
    );

    // windowsPE
    x.open_attrs("settings", &[("pass", "windowsPE")]);
    x.component("Microsoft-Windows-International-Core-WinPE");
    x.open("SetupUILanguage");
    x.leaf("UILanguage", &o.locale);
    x.close("SetupUILanguage");
    international(&mut x, o);
    x.close("component");
    x.component("Microsoft-Windows-Setup");
    disk_configuration(&mut x, o.firmware);
    x.open("ImageInstall");
    x.open("OSImage");
    x.open("InstallFrom");
    x.open("MetaData").add();
    let (key, value) = match &o.image {
        ImageChoice::Index(n) => ("/IMAGE/INDEX", n.to_string()),
        ImageChoice::Name(name) => ("/IMAGE/NAME", name.clone()),
    };
    x.leaf("Key", key);
    x.leaf("Value", &value);
    x.close("MetaData");
    x.close("InstallFrom");
    x.open("InstallTo");
    x.leaf("DiskID", "0");
    x.leaf("PartitionID", &windows_partition(o.firmware).to_string());
    x.close("InstallTo");
    x.leaf("InstallToAvailablePartition", "false");
    x.close("OSImage");
    x.close("ImageInstall");
    x.open("UserData");
    x.leaf("AcceptEula", "true");
    x.leaf("FullName", &o.user);
    if let Some(key) = &o.product_key {
        x.open("ProductKey");
        x.leaf("Key", key);
        x.leaf("WillShowUI", "OnError");
        x.close("ProductKey");
    }
    x.close("UserData");
    // No downloads during Setup: the install does not depend on the network.
    x.open("DynamicUpdate");
    x.leaf("Enable", "false");
    x.leaf("WillShowUI", "Never");
    x.close("DynamicUpdate");
    if o.bypass_checks {
        x.open("RunSynchronous");
        for (i, value) in LAB_CONFIG.iter().enumerate() {
            x.open("RunSynchronousCommand").add();
            x.leaf("Order", &(i + 1).to_string());
            x.leaf("Path", &format!(r#"reg.exe add "HKLM\SYSTEM\Setup\LabConfig" /v {value} /t REG_DWORD /d 1 /f"#));
            x.close("RunSynchronousCommand");
        }
        x.close("RunSynchronous");
    }
    x.close("component");
    x.close("settings");

    // offlineServicing
    x.open_attrs("settings", &[("pass", "offlineServicing")]);
    x.component("Microsoft-Windows-LUA-Settings");
    x.leaf("EnableLUA", if o.uac == Uac::On { "true" } else { "false" });
    x.close("component");
    x.close("settings");

    // specialize
    x.open_attrs("settings", &[("pass", "specialize")]);
    x.component("Microsoft-Windows-Shell-Setup");
    x.leaf("ComputerName", &o.computer_name);
    x.leaf("TimeZone", &o.timezone);
    x.close("component");
    x.component("Microsoft-Windows-Deployment");
    x.open("RunSynchronous");
    for (i, (path, what)) in [
        (BYPASS_NRO.to_owned(), "local account without a network"),
        (oem_copy_command(), "OEM media to C:\\OEM"),
        (stage_command("oobe"), "tell arena vm prepare that OOBE comes next"),
    ]
    .iter()
    .enumerate()
    {
        x.open("RunSynchronousCommand").add();
        x.leaf("Order", &(i + 1).to_string());
        x.leaf("Path", path);
        x.leaf("Description", what);
        x.close("RunSynchronousCommand");
    }
    x.close("RunSynchronous");
    x.close("component");
    x.close("settings");

    // oobeSystem
    x.open_attrs("settings", &[("pass", "oobeSystem")]);
    // No automatic device encryption: with a TPM attached Windows 11 may encrypt the
    // disk against that TPM, and every VM made from the golden image has its own.
    x.component("Microsoft-Windows-SecureStartup-FilterDriver");
    x.leaf("PreventDeviceEncryption", "true");
    x.close("component");
    x.component("Microsoft-Windows-International-Core");
    international(&mut x, o);
    x.close("component");
    x.component("Microsoft-Windows-Shell-Setup");
    x.open("UserAccounts");
    x.open("LocalAccounts");
    x.open("LocalAccount").add();
    x.leaf("Name", &o.user);
    x.leaf("Group", "Administrators");
    password(&mut x, &o.password);
    x.close("LocalAccount");
    x.close("LocalAccounts");
    x.close("UserAccounts");
    x.open("AutoLogon");
    x.leaf("Enabled", "true");
    x.leaf("Username", &o.user);
    // Setup wants a count; prep-autologon.ps1 removes it so auto-logon never runs out.
    x.leaf("LogonCount", "9999");
    password(&mut x, &o.password);
    x.close("AutoLogon");
    x.open("OOBE");
    for page in [
        "HideEULAPage",
        "HideLocalAccountScreen",
        "HideOEMRegistrationScreen",
        "HideOnlineAccountScreens",
        "HideWirelessSetupInOOBE",
    ] {
        x.leaf(page, "true");
    }
    x.leaf("ProtectYourPC", "3");
    x.close("OOBE");
    x.open("FirstLogonCommands");
    for (i, (command, what)) in [
        (stage_command("first-logon"), "tell arena vm prepare that the user logged on"),
        (FIRST_LOGON_COMMAND.to_owned(), "arena OEM install (setup.ps1)"),
    ]
    .iter()
    .enumerate()
    {
        x.open("SynchronousCommand").add();
        x.leaf("Order", &(i + 1).to_string());
        x.leaf("CommandLine", command);
        x.leaf("Description", what);
        x.leaf("RequiresUserInput", "false");
        x.close("SynchronousCommand");
    }
    x.close("FirstLogonCommands");
    x.close("component");
    x.close("settings");

    x.close("unattend");
    x.out
}

fn international(x: &mut Xml, o: &AnswerOptions) {
    x.leaf("InputLocale", &o.keyboard);
    x.leaf("SystemLocale", &o.locale);
    x.leaf("UILanguage", &o.locale);
    x.leaf("UserLocale", &o.locale);
}

fn password(x: &mut Xml, password: &str) {
    x.open("Password");
    x.leaf("Value", password);
    x.leaf("PlainText", "true");
    x.close("Password");
}

/// The partition Windows goes on: 3 on GPT (after EFI and MSR), 2 on MBR.
pub fn windows_partition(firmware: FirmwareKind) -> u32 {
    match firmware {
        FirmwareKind::Uefi => 3,
        FirmwareKind::Bios => 2,
    }
}

/// Microsoft's recommended layouts ("UEFI/GPT-based hard drive partitions",
/// "BIOS/MBR-based hard drive partitions"), without a recovery partition.
fn disk_configuration(x: &mut Xml, firmware: FirmwareKind) {
    x.open("DiskConfiguration");
    x.open("Disk").add();
    x.leaf("DiskID", "0");
    x.leaf("WillWipeDisk", "true");
    let created: &[(&str, Option<u32>)] = match firmware {
        FirmwareKind::Uefi => &[("EFI", Some(100)), ("MSR", Some(16)), ("Primary", None)],
        FirmwareKind::Bios => &[("Primary", Some(100)), ("Primary", None)],
    };
    x.open("CreatePartitions");
    for (i, (kind, size)) in created.iter().enumerate() {
        x.open("CreatePartition").add();
        x.leaf("Order", &(i + 1).to_string());
        x.leaf("Type", kind);
        match size {
            Some(mib) => x.leaf("Size", &mib.to_string()),
            None => x.leaf("Extend", "true"),
        };
        x.close("CreatePartition");
    }
    x.close("CreatePartitions");
    x.open("ModifyPartitions");
    let mut order = 0;
    let mut modify = |x: &mut Xml, id: u32, fields: &[(&str, &str)]| {
        order += 1;
        x.open("ModifyPartition").add();
        x.leaf("Order", &order.to_string());
        x.leaf("PartitionID", &id.to_string());
        for (name, value) in fields {
            x.leaf(name, value);
        }
        x.close("ModifyPartition");
    };
    match firmware {
        FirmwareKind::Uefi => {
            modify(x, 1, &[("Format", "FAT32"), ("Label", "System")]);
            modify(x, 3, &[("Format", "NTFS"), ("Label", "Windows"), ("Letter", "C")]);
        }
        FirmwareKind::Bios => {
            modify(x, 1, &[("Active", "true"), ("Format", "NTFS"), ("Label", "System")]);
            modify(x, 2, &[("Format", "NTFS"), ("Label", "Windows"), ("Letter", "C")]);
        }
    }
    x.close("ModifyPartitions");
    x.close("Disk");
    x.leaf("WillShowUI", "OnError");
    x.close("DiskConfiguration");
}

/// A small indenting XML writer; text and attribute values are escaped.
#[derive(Default)]
struct Xml {
    out: String,
    depth: usize,
}

impl Xml {
    fn raw(&mut self, text: &str) {
        self.out.push_str(text);
    }

    fn indent(&mut self) {
        for _ in 0..self.depth {
            self.out.push_str("  ");
        }
    }

    fn open(&mut self, name: &str) -> &mut Xml {
        self.open_attrs(name, &[])
    }

    fn open_attrs(&mut self, name: &str, attrs: &[(&str, &str)]) -> &mut Xml {
        self.indent();
        let _ = write!(self.out, "<{name}");
        for (key, value) in attrs {
            let _ = write!(self.out, " {key}=\"{}\"", escape(value));
        }
        self.out.push_str(">\n");
        self.depth += 1;
        self
    }

    /// Marks the element just opened as a list item (`wcm:action="add"`).
    fn add(&mut self) {
        let at = self.out.len() - 2;
        self.out.insert_str(at, " wcm:action=\"add\"");
    }

    fn component(&mut self, name: &str) {
        self.open_attrs(
            "component",
            &[
                ("name", name),
                ("processorArchitecture", "amd64"),
                ("publicKeyToken", PUBLIC_KEY_TOKEN),
                ("language", "neutral"),
                ("versionScope", "nonSxS"),
            ],
        );
    }

    fn leaf(&mut self, name: &str, text: &str) {
        self.indent();
        let _ = writeln!(self.out, "<{name}>{}</{name}>", escape(text));
    }

    fn close(&mut self, name: &str) {
        self.depth -= 1;
        self.indent();
        let _ = writeln!(self.out, "</{name}>");
    }
}

/// XML text and attribute escaping: the five predefined entities (the
/// apostrophe as a character reference), as the HTML report escapes.
fn escape(text: &str) -> String {
    crate::results::html::escape(text)
}

#[cfg(test)]
mod tests;
