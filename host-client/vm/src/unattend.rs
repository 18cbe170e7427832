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
//!   a network), passwords that never expire, Windows Update, Defender's
//!   real-time protection, SmartScreen, Smart App Control, Store updates and
//!   Widgets off ([`SPECIALIZE_POLICIES`]),
//!   and the copy of the OEM media to `C:\OEM` by a script on the media
//!   ([`oem_copy_command`], [`oem_copy_script`]).
//! - oobeSystem: no automatic device encryption (each VM has its own TPM),
//!   locale, the local administrator account, auto-logon, OOBE's pages hidden,
//!   the account's password set never to expire, the first logon's screen as
//!   upstream's ([`FIRST_LOGON_SCREEN`]: no unsupported-hardware watermark, no
//!   Task View, Widgets, Chat or Copilot button, no OneDrive setup), and
//!   `C:\OEM\install.bat` as the last first logon command.
//!
//! Every string written is checked against the maximum the reference gives for
//! its setting ([`LIMITS`], [`check_limits`]) before the file is used.

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
    /// No image named: Setup picks the image the product key is for (a
    /// multi-edition ISO whose image list could not be read here).
    ByKey,
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
            ImageChoice::Name(name) => {
                if let Some(edition) = Edition::find(name).filter(|e| e.refused) {
                    return Err(edition.refusal());
                }
            }
            ImageChoice::ByKey if self.product_key.is_none() => {
                return Err("no image is chosen and no product key says which: give --image-index or --edition".into())
            }
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
        // `net user`: "Passwords can be up to 127 characters long."
        if self.password.chars().count() > 127 {
            return Err("--password: a Windows password has at most 127 characters".into());
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

/// A Windows 11 edition `--edition` can name: its short name, the `EDITIONID`
/// its image carries in `install.wim`'s XML, the name Microsoft's media give it,
/// and the key Setup needs to pass its product-key page without a user key.
///
/// The keys are Microsoft's published Generic Volume License Keys ("Key
/// Management Services (KMS) client activation and product keys",
/// learn.microsoft.com/windows-server/get-started/kms-client-activation-keys,
/// table "Windows 11 and Windows 10 Semi-Annual Channel"): they choose the
/// edition and let Setup go on; they do not activate Windows (that needs a KMS
/// host or a license), which a benchmark VM does not need. Home has no such key
/// and is refused: it ignores the group policies the image relies on (Windows
/// Update off, no lock screen).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edition {
    /// What `--edition` takes (`pro`, `enterprise`, ...).
    pub short: &'static str,
    /// `EDITIONID` in the image list (`Professional`).
    pub id: &'static str,
    /// The name Windows 11 media give the image (`Windows 11 Pro`).
    pub name: &'static str,
    /// Microsoft's generic key for it.
    pub key: Option<&'static str>,
    /// Refused: the policies the image depends on do not apply to it.
    pub refused: bool,
}

/// The editions `--edition` knows (see [`Edition`]).
pub const EDITIONS: &[Edition] = &[
    Edition {
        short: "pro",
        id: "Professional",
        name: "Windows 11 Pro",
        key: Some("W269N-WFGWX-YVC9B-4J6C9-T83GX"),
        refused: false,
    },
    Edition {
        short: "pro-n",
        id: "ProfessionalN",
        name: "Windows 11 Pro N",
        key: Some("MH37W-N47XK-V7XM9-C7227-GCQG9"),
        refused: false,
    },
    Edition {
        short: "pro-workstations",
        id: "ProfessionalWorkstation",
        name: "Windows 11 Pro for Workstations",
        key: Some("NRG8B-VKK3Q-CXVCJ-9G2XF-6Q84J"),
        refused: false,
    },
    Edition {
        short: "pro-education",
        id: "ProfessionalEducation",
        name: "Windows 11 Pro Education",
        key: Some("6TP4R-GNPTD-KYYHQ-7B7DP-J447Y"),
        refused: false,
    },
    Edition {
        short: "education",
        id: "Education",
        name: "Windows 11 Education",
        key: Some("NW6C2-QMPVW-D7KKK-3GKT6-VCFB2"),
        refused: false,
    },
    Edition {
        short: "education-n",
        id: "EducationN",
        name: "Windows 11 Education N",
        key: Some("2WH4N-8QGBV-H22JP-CT43Q-MDWWJ"),
        refused: false,
    },
    Edition {
        short: "enterprise",
        id: "Enterprise",
        name: "Windows 11 Enterprise",
        key: Some("NPPR9-FWDCX-D2C8J-H872K-2YT43"),
        refused: false,
    },
    Edition {
        short: "enterprise-n",
        id: "EnterpriseN",
        name: "Windows 11 Enterprise N",
        key: Some("DPH2V-TTNVB-4X9Q3-TJR4H-KHJW4"),
        refused: false,
    },
    Edition { short: "home", id: "Core", name: "Windows 11 Home", key: None, refused: true },
    Edition { short: "home-n", id: "CoreN", name: "Windows 11 Home N", key: None, refused: true },
    Edition {
        short: "home-single-language",
        id: "CoreSingleLanguage",
        name: "Windows 11 Home Single Language",
        key: None,
        refused: true,
    },
    Edition {
        short: "home-country-specific",
        id: "CoreCountrySpecific",
        name: "Windows 11 Home China",
        key: None,
        refused: true,
    },
];

impl Edition {
    /// The edition `text` names: its short name, its `EDITIONID`, or its image
    /// name as Windows 11 media spell it or as some Windows 11 media still do
    /// ("Windows 10 Pro"); case and spacing do not matter.
    pub fn find(text: &str) -> Option<Edition> {
        let wanted = fold(text);
        EDITIONS.iter().copied().find(|e| {
            [e.short.to_owned(), e.id.to_owned(), e.name.to_owned(), e.name.replacen("Windows 11", "Windows 10", 1)]
                .iter()
                .any(|n| fold(n) == wanted)
        })
    }

    /// The edition whose `EDITIONID` is `id`.
    pub fn by_id(id: &str) -> Option<Edition> {
        EDITIONS.iter().copied().find(|e| e.id.eq_ignore_ascii_case(id.trim()))
    }

    /// Why this edition is refused.
    pub fn refusal(&self) -> String {
        format!(
            "{} (edition {}) is refused: Home ignores the group policies the image depends on (Windows Update off, no lock screen, no consumer pop-ups); choose pro, enterprise or education",
            self.name, self.id
        )
    }
}

/// The image and key the answer file gets from `--edition`, `--image-index` and
/// `--product-key`, with the ISO's image list when it could be read here
/// ([`super::iso::list_images`]).
///
/// - A known edition (`pro`, `Enterprise`, "Windows 11 Pro"): the image of that
///   edition by index when the list is known (by `EDITIONID`, else by name), or
///   no image and the edition's key (Setup installs what the key is for).
/// - Another name: the image of that `NAME` or `DISPLAYNAME` by index, or `/IMAGE/NAME`.
/// - An index (1 by default): that image, with its edition's key when the list says it.
///
/// `--product-key` replaces the generic key.
///
/// # Errors
///
/// Home (by name or by what the list says the image is), a name or index the
/// list does not hold (naming what it holds), or a known edition without the
/// list and without a key.
pub fn choose_image(
    edition: Option<&str>,
    index: Option<u32>,
    product_key: Option<String>,
    images: Option<&[super::iso::IsoImage]>,
) -> Result<(ImageChoice, Option<String>), String> {
    let listed = |images: &[super::iso::IsoImage]| {
        images
            .iter()
            .map(|i| format!("{} {:?} ({})", i.index, i.name, i.edition_id.as_deref().unwrap_or("?")))
            .collect::<Vec<_>>()
            .join(", ")
    };
    // The key of the image the list says `image` is, refusing Home.
    let key_of = |image: &super::iso::IsoImage| -> Result<Option<String>, String> {
        let edition = image.edition_id.as_deref().and_then(Edition::by_id);
        match edition {
            Some(e) if e.refused => Err(format!("image {}: {}", image.index, e.refusal())),
            Some(e) => Ok(product_key.clone().or(e.key.map(str::to_owned))),
            None => Ok(product_key.clone()),
        }
    };
    match (edition, index) {
        (Some(text), _) => {
            let known = Edition::find(text);
            if let Some(e) = known.filter(|e| e.refused) {
                return Err(e.refusal());
            }
            match (known, images) {
                (Some(e), Some(images)) => {
                    let image = images
                        .iter()
                        .find(|i| i.edition_id.as_deref().is_some_and(|id| id.eq_ignore_ascii_case(e.id)))
                        .or_else(|| images.iter().find(|i| Edition::find(&i.name) == Some(e)))
                        .ok_or_else(|| {
                            format!("--edition {text}: the ISO holds no {} image; it holds: {}", e.name, listed(images))
                        })?;
                    Ok((ImageChoice::Index(image.index), product_key.or(e.key.map(str::to_owned))))
                }
                (Some(e), None) => {
                    let key = product_key.or(e.key.map(str::to_owned));
                    if key.is_none() {
                        return Err(format!("--edition {text}: Microsoft publishes no generic key for it; give --product-key or --image-index"));
                    }
                    Ok((ImageChoice::ByKey, key))
                }
                (None, Some(images)) => {
                    let wanted = fold(text);
                    let image = images
                        .iter()
                        .find(|i| {
                            fold(&i.name) == wanted || i.display_name.as_deref().is_some_and(|d| fold(d) == wanted)
                        })
                        .ok_or_else(|| {
                            format!(
                                "--edition {text:?}: the ISO holds no image of that name; it holds: {}",
                                listed(images)
                            )
                        })?;
                    Ok((ImageChoice::Index(image.index), key_of(image)?))
                }
                (None, None) => Ok((ImageChoice::Name(text.to_owned()), product_key)),
            }
        }
        (None, index) => {
            let n = index.unwrap_or(1);
            match images {
                Some(images) => {
                    let image = images.iter().find(|i| i.index == n).ok_or_else(|| {
                        format!("--image-index {n}: the ISO holds no image {n}; it holds: {}", listed(images))
                    })?;
                    Ok((ImageChoice::Index(n), key_of(image)?))
                }
                None => Ok((ImageChoice::Index(n), product_key)),
            }
        }
    }
}

/// Lower case without spaces, dashes or underscores, for comparing edition names.
fn fold(text: &str) -> String {
    text.chars().filter(|c| !matches!(c, ' ' | '-' | '_')).flat_map(char::to_lowercase).collect()
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

/// The script at the OEM media's root that copies its `OEM\` folder to `C:\OEM`
/// (found by [`oem_copy_command`], which runs it).
pub const OEM_SCRIPT: &str = "ARENA-OEM.CMD";

/// The command the specialize pass runs to copy the OEM media's folder to
/// `C:\OEM`: it finds the drive by its marker file (CD-ROM letters vary) and
/// calls the script beside it, so the command stays far below the 259
/// characters Setup allows a `RunSynchronousCommand` `Path` ([`LIMITS`]).
pub fn oem_copy_command() -> String {
    format!(
        "cmd.exe /d /c for %d in (D E F G H I J K L M N O P Q R S T U V W X Y Z) do @if exist %d:\\{OEM_MARKER} call %d:\\{OEM_SCRIPT}"
    )
}

/// The script [`oem_copy_command`] calls: robocopy from the media's `OEM\` to
/// `C:\OEM`; a copy that fails says `arena-stage: oem-failed ...` on COM1 so
/// that prepare stops at once, naming it. CRLF line ends, as cmd.exe reads them.
pub fn oem_copy_script() -> String {
    [
        "@echo off",
        "rem Written by arena vm prepare: the specialize pass calls this script from the OEM media",
        "rem (found by ARENA-OEM.TXT beside it) to copy the media's OEM folder to C:\\OEM.",
        "robocopy \"%~d0\\OEM\" C:\\OEM /E /R:2 /W:2 /NP /NFL /NDL >NUL",
        "if %ERRORLEVEL% GEQ 8 (",
        "  echo arena-stage: oem-failed copying the OEM media to C:\\OEM: robocopy exit code %ERRORLEVEL%>COM1",
        "  exit /b 1",
        ")",
        "echo arena-oem: the OEM media were copied to C:\\OEM>COM1",
        "exit /b 0",
        "",
    ]
    .join("\r\n")
}

/// The policies the specialize pass writes, before the first logon and before
/// any script could fail: each a `reg.exe add` of the Group Policy value
/// Microsoft documents for it, since no unattend setting of Windows 11 turns
/// these off (docs/vm.md's comparison table lists each). `prep-automation.ps1`
/// writes them again, for images made another way.
pub const SPECIALIZE_POLICIES: &[(&str, &str)] = &[
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows\WindowsUpdate\AU" /v NoAutoUpdate /t REG_DWORD /d 1 /f"#,
        "Windows Update: no automatic updates (policy NoAutoUpdate)",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Real-Time Protection" /v DisableRealtimeMonitoring /t REG_DWORD /d 1 /f"#,
        "Defender: real-time protection off (policy DisableRealtimeMonitoring)",
    ),
    // Defender's path exclusions by policy (Microsoft Learn, "Configure and validate
    // exclusions based on file extension and folder location": Group Policy's
    // Microsoft Defender Antivirus > Exclusions > Path Exclusions, one value per
    // path, named by the path, value 0; WindowsDefender.admx writes the policy as
    // `Exclusions_Paths`=1 under `...\Windows Defender\Exclusions` and the list under
    // its `Paths` key). The guest's exes (install-guest.ps1's `-InstallDir`), its
    // data (token, logs, setup-status.json) and the OEM folder are never scanned
    // or quarantined, whether real-time protection stays on or not.
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions" /v Exclusions_Paths /t REG_DWORD /d 1 /f"#,
        "Defender: path exclusions by policy (Exclusions_Paths)",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions\Paths" /v "C:\Program Files\Arena" /t REG_DWORD /d 0 /f"#,
        "Defender: the guest's install folder excluded",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions\Paths" /v "C:\ProgramData\arena" /t REG_DWORD /d 0 /f"#,
        "Defender: the guest's data folder excluded",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions\Paths" /v "C:\OEM" /t REG_DWORD /d 0 /f"#,
        "Defender: the OEM folder excluded",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows\System" /v EnableSmartScreen /t REG_DWORD /d 0 /f"#,
        "SmartScreen for apps and files off (policy EnableSmartScreen)",
    ),
    (
        r#"reg.exe add "HKLM\SYSTEM\CurrentControlSet\Control\CI\Policy" /v VerifiedAndReputablePolicyState /t REG_DWORD /d 0 /f"#,
        "Smart App Control off, before its first evaluation (VerifiedAndReputablePolicyState)",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\WindowsStore" /v AutoDownload /t REG_DWORD /d 2 /f"#,
        "Microsoft Store: no automatic app updates (policy AutoDownload=2)",
    ),
    (
        r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Dsh" /v AllowNewsAndInterests /t REG_DWORD /d 0 /f"#,
        "no Widgets board or taskbar button (policy AllowNewsAndInterests)",
    ),
];

/// The first logon's screen as upstream's image draws it, written in the
/// user's own hive (`HKCU`) before the OEM install: no "System requirements not
/// met" watermark on a VM Windows 11 calls unsupported (the notification
/// cache's `SV1` and `SV2`, as WAA's answer file and dockur's logon script write them), no
/// Task View, Widgets, Chat or Copilot button on the taskbar, and no OneDrive
/// setup started at every logon. `prep-automation.ps1` writes them again, for
/// images made another way.
pub const FIRST_LOGON_SCREEN: &[(&str, &str)] = &[
    (
        r#"reg.exe add "HKCU\Control Panel\UnsupportedHardwareNotificationCache" /v SV1 /t REG_DWORD /d 0 /f"#,
        "no unsupported-hardware watermark (SV1)",
    ),
    (
        r#"reg.exe add "HKCU\Control Panel\UnsupportedHardwareNotificationCache" /v SV2 /t REG_DWORD /d 0 /f"#,
        "no unsupported-hardware watermark (SV2)",
    ),
    (
        r#"reg.exe add "HKCU\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced" /v ShowTaskViewButton /t REG_DWORD /d 0 /f"#,
        "no Task View button",
    ),
    (
        r#"reg.exe add "HKCU\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced" /v TaskbarDa /t REG_DWORD /d 0 /f"#,
        "no Widgets button (recent builds may refuse it; the specialize pass's policy hides it too)",
    ),
    (
        r#"reg.exe add "HKCU\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced" /v TaskbarMn /t REG_DWORD /d 0 /f"#,
        "no Chat button",
    ),
    (
        r#"reg.exe add "HKCU\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced" /v ShowCopilotButton /t REG_DWORD /d 0 /f"#,
        "no Copilot button",
    ),
    (
        r#"reg.exe delete "HKCU\Software\Microsoft\Windows\CurrentVersion\Run" /v OneDriveSetup /f"#,
        "no OneDrive setup at logon (its Run value removed)",
    ),
];

/// Passwords never expire: the local accounts' maximum password age becomes
/// unlimited (Windows' default is 42 days, after which the auto-logon stops at
/// "The user's password must be changed"). A machine policy, so the specialize
/// pass sets it before the account exists.
pub const PASSWORDS_NEVER_EXPIRE: &str = "net.exe accounts /maxpwage:unlimited";

/// The first logon command that marks the account's own password as never
/// expiring (as `Set-LocalUser -PasswordNeverExpires`), on top of [`PASSWORDS_NEVER_EXPIRE`].
pub fn password_never_expires_command(user: &str) -> String {
    format!(
        "powershell.exe -NoProfile -NonInteractive -Command \"Set-LocalUser -Name '{}' -PasswordNeverExpires $true\"",
        user.replace('\'', "''")
    )
}

/// The first logon command: the OEM install (it logs to `%ProgramData%\arena\logs`),
/// or, when the specialize pass did not copy it, a stage line that says so.
pub const FIRST_LOGON_COMMAND: &str = r"cmd.exe /d /c if exist C:\OEM\install.bat (C:\OEM\install.bat) else (echo arena-stage: oem-failed C:\OEM\install.bat is missing: the specialize pass did not copy the OEM media>COM1)";

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
    let chosen = match &o.image {
        ImageChoice::Index(n) => Some(("/IMAGE/INDEX", n.to_string())),
        ImageChoice::Name(name) => Some(("/IMAGE/NAME", name.clone())),
        // Setup installs the image the product key is for.
        ImageChoice::ByKey => None,
    };
    if let Some((key, value)) = chosen {
        x.open("InstallFrom");
        x.open("MetaData").add();
        x.leaf("Key", key);
        x.leaf("Value", &value);
        x.close("MetaData");
        x.close("InstallFrom");
    }
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
    for (i, (path, what)) in specialize_commands().iter().enumerate() {
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
    for (i, (command, what)) in first_logon_commands(&o.user).iter().enumerate() {
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

/// The values that keep start-up apps off the first desktop, so that it settles
/// (and a `ready` snapshot is not taken over them): the Store's automatic app
/// updates (Microsoft's WindowsStore.admx policy "Turn off Automatic Download and
/// Install of updates", `AutoDownload`=2 under `Policies\Microsoft\WindowsStore`),
/// the Widgets board (the Policy CSP's `NewsAndInterests/AllowNewsAndInterests`,
/// `AllowNewsAndInterests`=0 under `Policies\Microsoft\Dsh`) and OneDrive's per-user
/// setup (its `OneDriveSetup` value under the user's `CurrentVersion\Run` key,
/// which starts it at every logon).
const STARTUP_APP_VALUES: [&str; 3] = ["/v AutoDownload ", "/v AllowNewsAndInterests ", "/v OneDriveSetup "];

/// What the generated answer file turns off among the apps that start at logon,
/// in its own words (the image's sidecar records them).
pub fn startup_apps_off() -> Vec<String> {
    SPECIALIZE_POLICIES
        .iter()
        .chain(FIRST_LOGON_SCREEN)
        .filter(|(command, _)| STARTUP_APP_VALUES.iter().any(|value| command.contains(value)))
        .map(|(_, what)| (*what).to_owned())
        .collect()
}

/// The specialize pass's commands, in order: a local account without a network,
/// passwords that never expire, the policies, the OEM copy, the stage line.
pub fn specialize_commands() -> Vec<(String, String)> {
    let mut commands = vec![
        (BYPASS_NRO.to_owned(), "local account without a network".to_owned()),
        (PASSWORDS_NEVER_EXPIRE.to_owned(), "passwords never expire (maximum age unlimited)".to_owned()),
    ];
    commands.extend(SPECIALIZE_POLICIES.iter().map(|(path, what)| ((*path).to_owned(), (*what).to_owned())));
    commands.push((oem_copy_command(), "OEM media to C:\\OEM".to_owned()));
    commands.push((stage_command("oobe"), "tell arena vm prepare that OOBE comes next".to_owned()));
    commands
}

/// The first logon commands, in order: the stage line, the account's password,
/// the screen ([`FIRST_LOGON_SCREEN`]), the OEM install.
pub fn first_logon_commands(user: &str) -> Vec<(String, String)> {
    let mut commands = vec![
        (stage_command("first-logon"), "tell arena vm prepare that the user logged on".to_owned()),
        (password_never_expires_command(user), "the account's password never expires".to_owned()),
    ];
    commands.extend(FIRST_LOGON_SCREEN.iter().map(|(command, what)| ((*command).to_owned(), (*what).to_owned())));
    commands.push((FIRST_LOGON_COMMAND.to_owned(), "arena OEM install (setup.ps1)".to_owned()));
    commands
}

/// One documented maximum: the setting (its element names from the component
/// down, under pass `pass`), the most characters its value may have, and the
/// reference page that gives it
/// (learn.microsoft.com/windows-hardware/customize/desktop/unattend/PAGE).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limit {
    pub component: &'static str,
    pub path: &'static [&'static str],
    pub max_chars: usize,
    pub page: &'static str,
}

/// The maxima Microsoft's unattend reference gives for the string settings this
/// module writes; a setting the reference gives no maximum for is listed in
/// [`UNLIMITED`] with its page instead. Numbers (`Order` 1 to 500) are in
/// [`ORDER_RANGE`].
pub const LIMITS: &[Limit] = &[
    Limit {
        component: "Microsoft-Windows-Deployment",
        path: &["RunSynchronous", "RunSynchronousCommand", "Path"],
        max_chars: 259,
        page: "microsoft-windows-deployment-runsynchronous-runsynchronouscommand-path",
    },
    Limit {
        component: "Microsoft-Windows-Deployment",
        path: &["RunSynchronous", "RunSynchronousCommand", "Description"],
        max_chars: 256,
        page: "microsoft-windows-deployment-runsynchronous-runsynchronouscommand-description",
    },
    Limit {
        component: "Microsoft-Windows-Shell-Setup",
        path: &["FirstLogonCommands", "SynchronousCommand", "CommandLine"],
        max_chars: 1024,
        page: "microsoft-windows-shell-setup-firstlogoncommands-synchronouscommand-commandline",
    },
    Limit {
        component: "Microsoft-Windows-Shell-Setup",
        path: &["FirstLogonCommands", "SynchronousCommand", "Description"],
        max_chars: 256,
        page: "microsoft-windows-shell-setup-firstlogoncommands-synchronouscommand-description",
    },
    Limit {
        component: "Microsoft-Windows-Shell-Setup",
        path: &["ComputerName"],
        max_chars: 15,
        page: "microsoft-windows-shell-setup-computername",
    },
    Limit {
        component: "Microsoft-Windows-Shell-Setup",
        path: &["TimeZone"],
        max_chars: 256,
        page: "microsoft-windows-shell-setup-timezone",
    },
    Limit {
        component: "Microsoft-Windows-Shell-Setup",
        path: &["UserAccounts", "LocalAccounts", "LocalAccount", "Name"],
        max_chars: 256,
        page: "microsoft-windows-shell-setup-useraccounts-localaccounts-localaccount-name",
    },
    Limit {
        component: "Microsoft-Windows-Shell-Setup",
        path: &["AutoLogon", "Username"],
        max_chars: 256,
        page: "microsoft-windows-shell-setup-autologon-username",
    },
    Limit {
        component: "Microsoft-Windows-Setup",
        path: &["UserData", "FullName"],
        max_chars: 63,
        page: "microsoft-windows-setup-userdata-fullname",
    },
    Limit {
        component: "Microsoft-Windows-Setup",
        path: &["UserData", "ProductKey", "Key"],
        max_chars: 29,
        page: "microsoft-windows-setup-userdata-productkey-key",
    },
    Limit {
        component: "Microsoft-Windows-Setup",
        path: &["DiskConfiguration", "Disk", "ModifyPartitions", "ModifyPartition", "Label"],
        // FAT32 volume labels have 11 characters; NTFS ones 32.
        max_chars: 11,
        page: "microsoft-windows-setup-diskconfiguration-disk-modifypartitions-modifypartition-label",
    },
];

/// String settings written here whose reference page gives no maximum: the
/// component, the path, and the page. The limits test requires every string
/// written to be in [`LIMITS`] or here.
pub const UNLIMITED: &[(&str, &[&str], &str)] = &[
    (
        "Microsoft-Windows-Setup",
        &["RunSynchronous", "RunSynchronousCommand", "Path"],
        "microsoft-windows-setup-runsynchronous-runsynchronouscommand-path",
    ),
    (
        "Microsoft-Windows-Setup",
        &["ImageInstall", "OSImage", "InstallFrom", "MetaData", "Value"],
        "microsoft-windows-setup-imageinstall-osimage-installfrom-metadata-value",
    ),
    (
        "Microsoft-Windows-Shell-Setup",
        &["UserAccounts", "LocalAccounts", "LocalAccount", "Password", "Value"],
        "microsoft-windows-shell-setup-useraccounts-localaccounts-localaccount-password-value",
    ),
    (
        "Microsoft-Windows-Shell-Setup",
        &["AutoLogon", "Password", "Value"],
        "microsoft-windows-shell-setup-autologon-password-value",
    ),
];

/// `Order` of `RunSynchronousCommand` and `SynchronousCommand`: "an integer from 1 through 500".
pub const ORDER_RANGE: std::ops::RangeInclusive<u32> = 1..=500;

/// Values that are fixed words (`true`, `OnError`, `/IMAGE/INDEX`, ...), locale
/// tags or sizes, which the limits check does not measure: element names.
const FIXED_VALUES: &[&str] = &[
    "UILanguage",
    "InputLocale",
    "SystemLocale",
    "UserLocale",
    "DiskID",
    "WillWipeDisk",
    "Order",
    "Type",
    "Size",
    "Extend",
    "PartitionID",
    "Format",
    "Letter",
    "Active",
    "WillShowUI",
    "Key",
    "InstallToAvailablePartition",
    "AcceptEula",
    "Enable",
    "EnableLUA",
    "PreventDeviceEncryption",
    "Group",
    "PlainText",
    "Enabled",
    "LogonCount",
    "HideEULAPage",
    "HideLocalAccountScreen",
    "HideOEMRegistrationScreen",
    "HideOnlineAccountScreens",
    "HideWirelessSetupInOOBE",
    "ProtectYourPC",
    "RequiresUserInput",
];

/// Checks every value of an answer file against [`LIMITS`]: each string setting
/// must be within its documented maximum (or be one the reference gives none
/// for, [`UNLIMITED`], or a fixed word, [`FIXED_VALUES`]), and every `Order` in
/// [`ORDER_RANGE`].
///
/// # Errors
///
/// The first value out of bounds, naming the setting, its length, the maximum
/// and the reference page; or a string setting the tables do not know.
///
/// With `strict` off (a user's own answer file), settings the tables do not
/// know are let through; only known maxima are enforced.
pub fn check_limits(xml: &str, strict: bool) -> Result<(), String> {
    let doc = roxmltree::Document::parse(xml).map_err(|err| format!("the answer file is not XML: {err}"))?;
    for component in doc.descendants().filter(|n| n.has_tag_name("component")) {
        let name = component.attribute("name").unwrap_or_default();
        for leaf in component.descendants().filter(|n| n.is_element() && !n.children().any(|c| c.is_element())) {
            let path: Vec<&str> = leaf
                .ancestors()
                .take_while(|a| *a != component)
                .filter(|a| a.is_element())
                .map(|a| a.tag_name().name())
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect();
            let value = leaf.text().unwrap_or_default();
            let setting = format!("{name}/{}", path.join("/"));
            let last = path.last().copied().unwrap_or_default();
            if last == "Order" {
                let n: u32 = value.trim().parse().map_err(|_| format!("{setting}: {value:?} is not a number"))?;
                if !ORDER_RANGE.contains(&n) {
                    return Err(format!("{setting}: {n} is outside 1 to 500"));
                }
                continue;
            }
            if let Some(limit) = LIMITS.iter().find(|l| l.component == name && l.path == path.as_slice()) {
                let chars = value.chars().count();
                if chars > limit.max_chars {
                    return Err(format!(
                        "{setting} has {chars} characters; the unattend reference ({}) allows at most {}: {value:?}",
                        limit.page, limit.max_chars
                    ));
                }
                continue;
            }
            let unlimited = UNLIMITED.iter().any(|(c, p, _)| *c == name && *p == path.as_slice());
            if strict && !unlimited && !FIXED_VALUES.contains(&last) {
                return Err(format!("{setting}: no documented limit is known for this setting (add it to LIMITS)"));
            }
        }
    }
    Ok(())
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
    arena_results::html::escape(text)
}

#[cfg(test)]
mod tests;
