//! The generated answer file against the components, passes and settings of
//! Microsoft's unattend reference ([`DOCUMENTED`]), and the option checks.

use super::*;

const NS: &str = "urn:schemas-microsoft-com:unattend";
const WCM: &str = "http://schemas.microsoft.com/WMIConfig/2002/State";

/// Every check a Windows Setup answer file must pass here; returns the parsed text for more.
fn check_documented(xml: &str) {
    let doc = roxmltree::Document::parse(xml).unwrap_or_else(|err| panic!("not XML: {err}\n{xml}"));
    let root = doc.root_element();
    assert_eq!((root.tag_name().namespace(), root.tag_name().name()), (Some(NS), "unattend"));
    let mut last_pass = None;
    for settings in root.children().filter(|n| n.is_element()) {
        assert_eq!(settings.tag_name().name(), "settings");
        let pass = settings.attribute("pass").expect("a settings element without pass");
        let position = PASSES.iter().position(|p| *p == pass).unwrap_or_else(|| panic!("unknown pass {pass}"));
        assert!(last_pass < Some(position), "pass {pass} is out of Setup's order");
        last_pass = Some(position);
        for component in settings.children().filter(|n| n.is_element()) {
            assert_eq!(component.tag_name().name(), "component");
            let name = component.attribute("name").unwrap();
            assert_eq!(component.attribute("processorArchitecture"), Some("amd64"), "{name}");
            assert_eq!(component.attribute("publicKeyToken"), Some(PUBLIC_KEY_TOKEN), "{name}");
            assert_eq!(component.attribute("language"), Some("neutral"), "{name}");
            assert_eq!(component.attribute("versionScope"), Some("nonSxS"), "{name}");
            let allowed = DOCUMENTED
                .iter()
                .find(|(c, p, _)| *c == name && *p == pass)
                .unwrap_or_else(|| panic!("{name} is not documented in pass {pass}"))
                .2;
            for setting in component.children().filter(|n| n.is_element()) {
                let setting = setting.tag_name().name();
                assert!(allowed.contains(&setting), "{name}/{setting} is not documented in pass {pass}");
            }
        }
    }
    // List items carry wcm:action="add", and their Order values run 1, 2, 3... per list.
    for node in doc.descendants().filter(|n| n.is_element()) {
        let item = matches!(
            node.tag_name().name(),
            "Disk"
                | "CreatePartition"
                | "ModifyPartition"
                | "RunSynchronousCommand"
                | "LocalAccount"
                | "SynchronousCommand"
                | "MetaData"
        );
        assert_eq!(node.attribute((WCM, "action")).is_some(), item, "{}", node.tag_name().name());
        let orders: Vec<u32> = node
            .children()
            .filter(|c| c.is_element())
            .filter_map(|c| c.children().find(|g| g.has_tag_name((NS, "Order"))))
            .map(|o| o.text().unwrap().parse().unwrap())
            .collect();
        assert_eq!(orders, (1..=orders.len() as u32).collect::<Vec<_>>(), "{}", node.tag_name().name());
    }
}

fn text_of<'a>(doc: &'a roxmltree::Document<'_>, pass: &str, path: &[&str]) -> Vec<&'a str> {
    let mut nodes: Vec<roxmltree::Node<'_, '_>> = doc
        .root_element()
        .children()
        .filter(|n| n.has_tag_name((NS, "settings")) && n.attribute("pass") == Some(pass))
        .flat_map(|s| s.children().filter(|n| n.is_element()).collect::<Vec<_>>())
        .collect();
    for name in path {
        nodes = nodes.iter().flat_map(|n| n.children().filter(|c| c.has_tag_name((NS, *name)))).collect();
    }
    nodes.iter().map(|n| n.text().unwrap_or("")).collect()
}

#[test]
fn the_default_file_uses_only_documented_settings_and_answers_every_page() {
    let xml = render(&AnswerOptions::new());
    check_documented(&xml);
    let doc = roxmltree::Document::parse(&xml).unwrap();
    // The image, the EULA, the disk, the bypass keys.
    assert_eq!(
        text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallFrom", "MetaData", "Key"]),
        ["/IMAGE/INDEX"]
    );
    assert_eq!(text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallFrom", "MetaData", "Value"]), ["1"]);
    assert_eq!(text_of(&doc, "windowsPE", &["UserData", "AcceptEula"]), ["true"]);
    let paths = text_of(&doc, "windowsPE", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    for key in LAB_CONFIG {
        assert!(paths.iter().any(|p| p.contains(r"HKLM\SYSTEM\Setup\LabConfig") && p.contains(key)), "{paths:?}");
    }
    // BIOS: MBR, the active system partition, Windows on partition 2 as C:.
    assert_eq!(
        text_of(&doc, "windowsPE", &["DiskConfiguration", "Disk", "CreatePartitions", "CreatePartition", "Type"]),
        ["Primary", "Primary"]
    );
    assert_eq!(text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallTo", "PartitionID"]), ["2"]);
    // UAC off, the local account, auto-logon as it, OOBE's pages hidden, the OEM install.
    assert_eq!(text_of(&doc, "offlineServicing", &["EnableLUA"]), ["false"]);
    assert_eq!(text_of(&doc, "oobeSystem", &["PreventDeviceEncryption"]), ["true"]);
    assert_eq!(text_of(&doc, "oobeSystem", &["UserAccounts", "LocalAccounts", "LocalAccount", "Name"]), ["Docker"]);
    assert_eq!(text_of(&doc, "oobeSystem", &["AutoLogon", "Username"]), ["Docker"]);
    assert_eq!(text_of(&doc, "oobeSystem", &["AutoLogon", "Enabled"]), ["true"]);
    assert_eq!(text_of(&doc, "oobeSystem", &["OOBE", "HideOnlineAccountScreens"]), ["true"]);
    let first_logon = text_of(&doc, "oobeSystem", &["FirstLogonCommands", "SynchronousCommand", "CommandLine"]);
    assert_eq!(first_logon[0], stage_command("first-logon"));
    assert_eq!(first_logon.last().copied(), Some(FIRST_LOGON_COMMAND));
    let specialize = text_of(&doc, "specialize", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    assert_eq!(specialize[0], BYPASS_NRO);
    let copy = specialize.iter().find(|p| p.contains(OEM_MARKER)).expect("the OEM copy");
    assert!(copy.contains(OEM_SCRIPT), "{specialize:?}");
    assert!(oem_copy_script().contains(r#"robocopy "%~d0\OEM" C:\OEM"#));
    assert_eq!(specialize.last().copied(), Some("cmd.exe /d /c echo arena-stage: oobe>COM1"));
    check_limits(&xml, true).unwrap();
}

/// The accounts' passwords never expire, set where no later script can miss
/// it: the maximum password age in the specialize pass (a machine policy, so it
/// holds before the account exists) and the account's own flag at its first
/// logon, before the OEM install runs.
#[test]
fn the_password_never_expires_from_the_specialize_pass_and_the_first_logon() {
    let mut o = AnswerOptions::new();
    o.user = "O'Brien".into();
    let xml = render(&o);
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let specialize = text_of(&doc, "specialize", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    let copy = specialize.iter().position(|p| p.contains(OEM_SCRIPT)).unwrap();
    let policy = specialize.iter().position(|p| *p == "net.exe accounts /maxpwage:unlimited").expect("maxpwage");
    assert!(policy < copy, "{specialize:?}");
    let first_logon = text_of(&doc, "oobeSystem", &["FirstLogonCommands", "SynchronousCommand", "CommandLine"]);
    let own = first_logon.iter().position(|c| c.contains("-PasswordNeverExpires $true")).expect("the account's flag");
    assert!(first_logon[own].contains("-Name 'O''Brien'"), "{first_logon:?}");
    assert!(own < first_logon.iter().position(|c| *c == FIRST_LOGON_COMMAND).unwrap());
}

/// Windows Update, Defender's real-time protection, SmartScreen and Smart App
/// Control are turned off in the specialize pass, before the OEM copy.
#[test]
fn the_policies_are_written_in_the_specialize_pass() {
    let xml = render(&AnswerOptions::new());
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let specialize = text_of(&doc, "specialize", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    for (needle, value) in [
        (r"WindowsUpdate\AU", "NoAutoUpdate /t REG_DWORD /d 1"),
        (r"Windows Defender\Real-Time Protection", "DisableRealtimeMonitoring /t REG_DWORD /d 1"),
        (r"Windows\System", "EnableSmartScreen /t REG_DWORD /d 0"),
        (r"CI\Policy", "VerifiedAndReputablePolicyState /t REG_DWORD /d 0"),
    ] {
        assert!(specialize.iter().any(|p| p.contains(needle) && p.contains(value)), "{needle}: {specialize:?}");
    }
}

/// Defender never scans the guest's exes, its data or the OEM folder: the path
/// exclusions policy is on and lists each, as REG_DWORD 0 named by the path, in
/// the specialize pass, before the OEM copy puts the exes on the disk.
#[test]
fn defender_excludes_the_guests_folders_by_policy_before_the_oem_copy() {
    let xml = render(&AnswerOptions::new());
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let specialize = text_of(&doc, "specialize", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    let copy = specialize.iter().position(|p| p.contains(OEM_SCRIPT)).unwrap();
    let on = specialize
        .iter()
        .position(|p| p.contains(r#""HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions" /v Exclusions_Paths /t REG_DWORD /d 1 /f"#))
        .unwrap_or_else(|| panic!("no Exclusions_Paths: {specialize:?}"));
    assert!(on < copy);
    for folder in [r"C:\Program Files\Arena", r"C:\ProgramData\arena", r"C:\OEM"] {
        let line = format!(
            r#"reg.exe add "HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions\Paths" /v "{folder}" /t REG_DWORD /d 0 /f"#
        );
        let at = specialize.iter().position(|p| *p == line).unwrap_or_else(|| panic!("{line}: {specialize:?}"));
        assert!(at < copy, "{folder} is excluded only after the copy");
    }
}

/// Upstream's screen at first logon: the unsupported-hardware watermark's
/// cache (`SV1`, `SV2`) and the taskbar buttons are written in the user's hive
/// before the OEM install, the Store's automatic updates are off by policy in
/// the specialize pass, and OneDrive's setup is taken out of the Run key.
#[test]
fn the_first_logon_draws_upstreams_screen_and_the_store_does_not_update() {
    let xml = render(&AnswerOptions::new());
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let first_logon = text_of(&doc, "oobeSystem", &["FirstLogonCommands", "SynchronousCommand", "CommandLine"]);
    let install = first_logon.iter().position(|c| *c == FIRST_LOGON_COMMAND).expect("the OEM install");
    for (key, value) in [
        (r"HKCU\Control Panel\UnsupportedHardwareNotificationCache", "/v SV1 /t REG_DWORD /d 0 /f"),
        (r"HKCU\Control Panel\UnsupportedHardwareNotificationCache", "/v SV2 /t REG_DWORD /d 0 /f"),
        (r"Explorer\Advanced", "/v ShowTaskViewButton /t REG_DWORD /d 0"),
        (r"Explorer\Advanced", "/v TaskbarDa /t REG_DWORD /d 0"),
        (r"Explorer\Advanced", "/v TaskbarMn /t REG_DWORD /d 0"),
        (r"Explorer\Advanced", "/v ShowCopilotButton /t REG_DWORD /d 0"),
        (r"reg.exe delete HKCU\Software\Microsoft\Windows\CurrentVersion\Run", "/v OneDriveSetup /f"),
    ] {
        let at = first_logon
            .iter()
            .position(|c| c.replace('"', "").contains(key) && c.contains(value))
            .unwrap_or_else(|| panic!("{key} {value}: {first_logon:?}"));
        assert!(at < install, "{value} after the OEM install: {first_logon:?}");
    }
    let specialize = text_of(&doc, "specialize", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    assert!(
        specialize.iter().any(|p| p.contains(r"HKLM\SOFTWARE\Policies\Microsoft\WindowsStore")
            && p.contains("/v AutoDownload /t REG_DWORD /d 2 /f")),
        "{specialize:?}"
    );
    check_limits(&xml, true).unwrap();
}

/// The start-up apps the sidecar records as off are the ones the answer file
/// turns off: each of the three is a command the file carries.
#[test]
fn the_startup_apps_off_are_the_answer_files_own_commands() {
    let off = startup_apps_off();
    assert_eq!(off.len(), 3, "{off:?}");
    for what in ["AutoDownload=2", "AllowNewsAndInterests", "OneDrive"] {
        assert!(off.iter().any(|s| s.contains(what)), "{what}: {off:?}");
    }
    let commands: Vec<(String, String)> =
        specialize_commands().into_iter().chain(first_logon_commands("Docker")).collect();
    for note in &off {
        assert!(commands.iter().any(|(_, what)| what == note), "{note} is no command of the answer file");
    }
}

/// Every string the generator writes, for both firmware paths and every
/// option that changes the file (UAC, bypass keys, image by index, by name and
/// by key, a product key, long names), is within the maximum Microsoft's
/// unattend reference gives for its setting ([`LIMITS`], each with its page),
/// or is a setting whose page gives none ([`UNLIMITED`]).
#[test]
fn every_generated_string_is_within_its_documented_maximum() {
    let mut variants = Vec::new();
    for firmware in [FirmwareKind::Bios, FirmwareKind::Uefi] {
        for uac in [Uac::Off, Uac::On] {
            for image in
                [ImageChoice::Index(6), ImageChoice::Name("Windows 11 Pro for Workstations".into()), ImageChoice::ByKey]
            {
                let mut o = AnswerOptions::new();
                o.firmware = firmware;
                o.uac = uac;
                o.bypass_checks = firmware == FirmwareKind::Bios;
                o.image = image;
                o.product_key = Some("NRG8B-VKK3Q-CXVCJ-9G2XF-6Q84J".into());
                // The longest values the option checks let through.
                o.user = "u".repeat(20);
                o.password = "p".repeat(127);
                o.computer_name = "C".repeat(15);
                o.timezone = "Pacific Standard Time_dstoff".into();
                variants.push(o);
            }
        }
    }
    for o in &variants {
        o.check().unwrap();
        let xml = render(o);
        check_documented(&xml);
        check_limits(&xml, true).unwrap_or_else(|err| panic!("{err}\n{xml}"));
    }
    // The tables cite a page for every maximum.
    for limit in LIMITS {
        assert!(limit.page.starts_with(&limit.component.to_lowercase()), "{limit:?}");
        assert!(limit.max_chars > 0);
    }
    for (component, _, page) in UNLIMITED {
        assert!(page.starts_with(&component.to_lowercase()), "{page}");
    }
}

/// The check itself: a specialize command of 260 characters (one past the 259
/// of `RunSynchronousCommand/Path`) fails, naming the setting and the page;
/// 259 passes; an Order of 501 and an unknown setting fail.
#[test]
fn the_limits_check_fails_on_a_260_character_specialize_command() {
    let xml = render(&AnswerOptions::new());
    let swap =
        |path: &str| xml.replacen(&format!("<Path>{}</Path>", escape(BYPASS_NRO)), &format!("<Path>{path}</Path>"), 1);
    let err = check_limits(&swap(&"x".repeat(260)), true).unwrap_err();
    assert!(err.contains("RunSynchronousCommand/Path has 260 characters"), "{err}");
    assert!(
        err.contains("microsoft-windows-deployment-runsynchronous-runsynchronouscommand-path") && err.contains("259")
    );
    check_limits(&swap(&"x".repeat(259)), true).unwrap();
    // Entities count as the one character they stand for.
    check_limits(&swap(&"&amp;".repeat(259)), true).unwrap();
    assert!(check_limits(&xml.replacen("<Order>1</Order>", "<Order>501</Order>", 1), true)
        .unwrap_err()
        .contains("501"));
    let unknown = xml.replacen("<TimeZone>UTC</TimeZone>", "<TimeZone>UTC</TimeZone><Themes>x</Themes>", 1);
    assert!(check_limits(&unknown, true).unwrap_err().contains("no documented limit"));
    check_limits(&unknown, false).unwrap();
    // The old copy command, 350 characters of PowerShell, would have failed here.
    let old = format!("powershell.exe -NoProfile -ExecutionPolicy Bypass -Command \"{}\"", "x".repeat(290));
    assert!(check_limits(&swap(&old), true).is_err());
    assert!(oem_copy_command().len() < 259, "{}", oem_copy_command().len());
}

fn images() -> Vec<crate::iso::IsoImage> {
    let image = |index, name: &str, id: &str| crate::iso::IsoImage {
        index,
        name: name.into(),
        display_name: None,
        edition_id: Some(id.into()),
        default_language: Some("en-US".into()),
    };
    vec![
        image(1, "Windows 11 Home", "Core"),
        // Some Windows 11 media still name the image as Windows 10 did.
        image(2, "Windows 10 Pro", "Professional"),
        image(3, "Windows 11 Education", "Education"),
        image(4, "Windows 11 Enterprise", "Enterprise"),
    ]
}

/// `--edition pro`, `--edition enterprise` and `--image-index N` give the image
/// and the key each needs, with the ISO's image list and without it;
/// `--edition home`, and an index whose image is Home, are refused.
#[test]
fn editions_and_indexes_choose_the_image_and_the_generic_key() {
    let list = images();
    let pro = Some("W269N-WFGWX-YVC9B-4J6C9-T83GX".to_owned());
    let enterprise = Some("NPPR9-FWDCX-D2C8J-H872K-2YT43".to_owned());
    // With the list: by EDITIONID, whatever the image's name says.
    assert_eq!(choose_image(Some("pro"), None, None, Some(&list)).unwrap(), (ImageChoice::Index(2), pro.clone()));
    assert_eq!(
        choose_image(Some("Windows 11 Pro"), None, None, Some(&list)).unwrap(),
        (ImageChoice::Index(2), pro.clone())
    );
    assert_eq!(
        choose_image(Some("Professional"), None, None, Some(&list)).unwrap(),
        (ImageChoice::Index(2), pro.clone())
    );
    assert_eq!(
        choose_image(Some("enterprise"), None, None, Some(&list)).unwrap(),
        (ImageChoice::Index(4), enterprise.clone())
    );
    assert_eq!(
        choose_image(None, Some(3), None, Some(&list)).unwrap().1.as_deref(),
        Some("NW6C2-QMPVW-D7KKK-3GKT6-VCFB2")
    );
    // A user's key wins.
    let mine = Some("AAAAA-BBBBB-CCCCC-DDDDD-EEEEE".to_owned());
    assert_eq!(choose_image(Some("pro"), None, mine.clone(), Some(&list)).unwrap().1, mine);
    // Without it: the key chooses the image, or the index stands alone.
    assert_eq!(choose_image(Some("pro"), None, None, None).unwrap(), (ImageChoice::ByKey, pro));
    assert_eq!(choose_image(Some("enterprise"), None, None, None).unwrap(), (ImageChoice::ByKey, enterprise));
    assert_eq!(choose_image(None, Some(6), None, None).unwrap(), (ImageChoice::Index(6), None));
    assert_eq!(choose_image(None, None, None, None).unwrap(), (ImageChoice::Index(1), None));
    assert_eq!(
        choose_image(Some("Windows 11 SE"), None, None, None).unwrap(),
        (ImageChoice::Name("Windows 11 SE".into()), None)
    );
    // Home, by name or by what the list says image 1 is, and what the ISO lacks.
    for refused in [
        choose_image(Some("home"), None, None, None),
        choose_image(Some("Windows 11 Home"), None, None, Some(&list)),
        choose_image(None, Some(1), None, Some(&list)),
        choose_image(None, None, None, Some(&list)),
    ] {
        let err = refused.unwrap_err();
        assert!(err.contains("Home") && err.contains("refused"), "{err}");
    }
    let err = choose_image(Some("pro-workstations"), None, None, Some(&list)).unwrap_err();
    assert!(
        err.contains("holds no Windows 11 Pro for Workstations image") && err.contains("4 \"Windows 11 Enterprise\""),
        "{err}"
    );
    assert!(choose_image(None, Some(9), None, Some(&list)).unwrap_err().contains("no image 9"));

    // The answer files: a key-only choice writes no image, an index writes it, both write the key.
    let mut o = AnswerOptions::new();
    (o.image, o.product_key) = choose_image(Some("enterprise"), None, None, None).unwrap();
    o.check().unwrap();
    let xml = render(&o);
    check_documented(&xml);
    let doc = roxmltree::Document::parse(&xml).unwrap();
    assert!(text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallFrom"]).is_empty());
    assert_eq!(text_of(&doc, "windowsPE", &["UserData", "ProductKey", "Key"]), ["NPPR9-FWDCX-D2C8J-H872K-2YT43"]);
    (o.image, o.product_key) = choose_image(Some("pro"), None, None, Some(&list)).unwrap();
    let xml = render(&o);
    let doc = roxmltree::Document::parse(&xml).unwrap();
    assert_eq!(text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallFrom", "MetaData", "Value"]), ["2"]);
    assert_eq!(text_of(&doc, "windowsPE", &["UserData", "ProductKey", "Key"]), ["W269N-WFGWX-YVC9B-4J6C9-T83GX"]);
    // The checks refuse Home by name too, and a key-only choice without a key.
    o.image = ImageChoice::Name("Windows 11 Home".into());
    assert!(o.check().unwrap_err().contains("refused"));
    o.image = ImageChoice::ByKey;
    o.product_key = None;
    assert!(o.check().unwrap_err().contains("no image is chosen"));
}

#[test]
fn uefi_with_a_tpm_gets_gpt_and_no_bypass_keys() {
    let mut o = AnswerOptions::new();
    o.firmware = FirmwareKind::Uefi;
    o.bypass_checks = false;
    o.uac = Uac::On;
    o.image = ImageChoice::Name("Windows 11 Pro".into());
    o.product_key = Some("VK7JG-NPHTM-C97JM-9MPGT-3V66T".into());
    let xml = render(&o);
    check_documented(&xml);
    let doc = roxmltree::Document::parse(&xml).unwrap();
    assert_eq!(
        text_of(&doc, "windowsPE", &["DiskConfiguration", "Disk", "CreatePartitions", "CreatePartition", "Type"]),
        ["EFI", "MSR", "Primary"]
    );
    assert_eq!(
        text_of(&doc, "windowsPE", &["DiskConfiguration", "Disk", "ModifyPartitions", "ModifyPartition", "Format"]),
        ["FAT32", "NTFS"]
    );
    assert_eq!(text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallTo", "PartitionID"]), ["3"]);
    assert_eq!(
        text_of(&doc, "windowsPE", &["ImageInstall", "OSImage", "InstallFrom", "MetaData", "Value"]),
        ["Windows 11 Pro"]
    );
    assert_eq!(text_of(&doc, "windowsPE", &["UserData", "ProductKey", "Key"]), ["VK7JG-NPHTM-C97JM-9MPGT-3V66T"]);
    assert!(text_of(&doc, "windowsPE", &["RunSynchronous"]).is_empty());
    assert!(!xml.contains("LabConfig"));
    assert_eq!(text_of(&doc, "offlineServicing", &["EnableLUA"]), ["true"]);
}

#[test]
fn values_are_escaped_and_bad_options_are_named() {
    let mut o = AnswerOptions::new();
    o.password = "a<b&\"c'".into();
    let xml = render(&o);
    check_documented(&xml);
    let doc = roxmltree::Document::parse(&xml).unwrap();
    assert_eq!(text_of(&doc, "oobeSystem", &["AutoLogon", "Password", "Value"]), ["a<b&\"c'"]);
    assert!(o.check().is_ok());

    let check = |change: &dyn Fn(&mut AnswerOptions), needle: &str| {
        let mut o = AnswerOptions::new();
        change(&mut o);
        let err = o.check().unwrap_err();
        assert!(err.contains(needle), "{err}");
    };
    check(&|o| o.image = ImageChoice::Index(0), "--image-index");
    check(&|o| o.image = ImageChoice::Name(" ".into()), "--edition");
    check(&|o| o.product_key = Some("ABCDE-12345".into()), "--product-key");
    check(&|o| o.user = "a/b".into(), "--user");
    check(&|o| o.user = "x".repeat(21), "--user");
    check(&|o| o.locale = "english".into(), "--locale");
    check(&|o| o.keyboard = "0409".into(), "--keyboard");
    check(&|o| o.timezone = "<UTC>".into(), "--timezone");
    check(&|o| o.computer_name = "a-name-longer-than-15".into(), "--computer-name");
    check(&|o| o.computer_name = "12345".into(), "--computer-name");
    let mut o = AnswerOptions::new();
    o.keyboard = "0409:00000409;0407:00000407".into();
    o.computer_name = "ARENA-1".into();
    o.timezone = "Pacific Standard Time".into();
    assert!(o.check().is_ok());
}

#[test]
fn the_checker_itself_refuses_an_undocumented_setting_and_a_wrong_token() {
    let xml = render(&AnswerOptions::new());
    let wrong = xml.replacen("<ComputerName>", "<ComputerNames>", 1).replacen("</ComputerName>", "</ComputerNames>", 1);
    assert!(std::panic::catch_unwind(|| check_documented(&wrong)).is_err());
    let wrong = xml.replacen(PUBLIC_KEY_TOKEN, "0000000000000000", 1);
    assert!(std::panic::catch_unwind(|| check_documented(&wrong)).is_err());
    let wrong = xml.replacen("pass=\"specialize\"", "pass=\"windowsPE\"", 1);
    assert!(std::panic::catch_unwind(|| check_documented(&wrong)).is_err());
}
