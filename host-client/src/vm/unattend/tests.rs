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
    assert_eq!(
        text_of(&doc, "oobeSystem", &["FirstLogonCommands", "SynchronousCommand", "CommandLine"]),
        [stage_command("first-logon").as_str(), FIRST_LOGON_COMMAND]
    );
    let specialize = text_of(&doc, "specialize", &["RunSynchronous", "RunSynchronousCommand", "Path"]);
    assert_eq!(specialize[0], BYPASS_NRO);
    assert!(specialize[1].contains(OEM_MARKER) && specialize[1].contains(r"C:\OEM"), "{specialize:?}");
    assert_eq!(specialize[2], "cmd.exe /d /c echo arena-stage: oobe>COM1");
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
