//! Microsoft Defender's state as the doctor reports it: Tamper Protection,
//! real-time protection and the detections Defender recorded.
//!
//! The Windows backend asks Defender's own PowerShell module ([`SCRIPT`]:
//! `Get-MpComputerStatus`, `Get-MpThreat`, `Get-MpThreatDetection`, documented in
//! Microsoft Learn's Defender module reference) and [`parse`] reads its JSON, so
//! the reading is tested on every platform. A backend without Defender (the
//! stub) reports every fact as unknown and no detections ([`DefenderStatus::absent`]).

use serde::Deserialize;

/// What the doctor learns of Defender; `None` is "unknown".
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DefenderStatus {
    /// `Get-MpComputerStatus`'s `IsTamperProtected`.
    pub tamper_protection: Option<bool>,
    /// `RealTimeProtectionEnabled`.
    pub realtime: Option<bool>,
    /// `AntivirusEnabled`.
    pub antivirus: Option<bool>,
    /// `Get-MpThreatDetection`'s records, `None` when they could not be read.
    pub detections: Option<Vec<Detection>>,
    /// Why something is unknown.
    pub notes: Vec<String>,
}

/// One detection: the threat's name and the files or processes it named.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Detection {
    pub threat: String,
    pub time: String,
    pub resources: Vec<String>,
}

impl Detection {
    /// Whether it names the guest's own files (its install or data folder, the
    /// OEM folder, or one of its exes): Defender took the guest.
    pub fn touches_guest(&self) -> bool {
        self.resources.iter().any(|r| {
            let r = r.to_ascii_lowercase();
            ["arena-guest", r"\program files\arena\", r"\programdata\arena\", r":\oem\"].iter().any(|n| r.contains(n))
        })
    }
}

impl DefenderStatus {
    /// A backend without Defender: everything unknown, no detections.
    pub fn absent(why: &str) -> DefenderStatus {
        DefenderStatus { notes: vec![why.to_owned()], ..DefenderStatus::default() }
    }

    /// The doctor's line: `Tamper Protection on, real-time protection off,
    /// antivirus on, 0 detections`.
    pub fn summary(&self) -> String {
        let word = |v: Option<bool>| match v {
            Some(true) => "on",
            Some(false) => "off",
            None => "unknown",
        };
        let detections = match &self.detections {
            None => "detections unknown".to_owned(),
            Some(list) if list.is_empty() => "no detections".to_owned(),
            Some(list) => format!(
                "{} detection(s): {}",
                list.len(),
                list.iter()
                    .map(|d| format!("{} at {} ({})", d.threat, d.time, d.resources.join(", ")))
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        };
        let mut line = format!(
            "Tamper Protection {}, real-time protection {}, antivirus {}, {detections}",
            word(self.tamper_protection),
            word(self.realtime),
            word(self.antivirus)
        );
        if !self.notes.is_empty() {
            line.push_str(&format!(" ({})", self.notes.join("; ")));
        }
        line
    }

    /// The detections that name the guest's own files.
    pub fn guest_detections(&self) -> Vec<&Detection> {
        self.detections.iter().flatten().filter(|d| d.touches_guest()).collect()
    }
}

/// The PowerShell the Windows backend runs: one compressed JSON object, each
/// part caught on its own (Defender off or replaced by another antivirus makes
/// `Get-MpComputerStatus` fail; that is a fact, not the doctor's failure).
pub const SCRIPT: &str = r#"$ErrorActionPreference = 'Stop'
$out = [ordered]@{}
try {
  $s = Get-MpComputerStatus
  $out.tamper_protection = [bool]$s.IsTamperProtected
  $out.realtime = [bool]$s.RealTimeProtectionEnabled
  $out.antivirus = [bool]$s.AntivirusEnabled
} catch { $out.status_error = [string]$_.Exception.Message }
try {
  $names = @{}
  foreach ($t in @(Get-MpThreat)) { $names[[string]$t.ThreatID] = [string]$t.ThreatName }
  $out.detections = @(@(Get-MpThreatDetection) | ForEach-Object {
    [ordered]@{ threat = $names[[string]$_.ThreatID]; time = [string]$_.InitialDetectionTime; resources = @($_.Resources | ForEach-Object { [string]$_ }) }
  })
} catch { $out.detections_error = [string]$_.Exception.Message }
ConvertTo-Json -InputObject $out -Depth 4 -Compress
"#;

#[derive(Deserialize)]
struct Raw {
    tamper_protection: Option<bool>,
    realtime: Option<bool>,
    antivirus: Option<bool>,
    status_error: Option<String>,
    detections: Option<serde_json::Value>,
    detections_error: Option<String>,
}

/// A JSON value that is one string or a list of them (PowerShell writes a
/// one-element list as the element alone in some versions).
fn strings(value: Option<&serde_json::Value>) -> Vec<String> {
    match value {
        Some(serde_json::Value::String(s)) => vec![s.clone()],
        Some(serde_json::Value::Array(items)) => items.iter().filter_map(|i| i.as_str().map(str::to_owned)).collect(),
        _ => Vec::new(),
    }
}

/// Reads [`SCRIPT`]'s output.
///
/// # Errors
///
/// The output is not the JSON object the script writes; the message quotes its start.
pub fn parse(stdout: &str) -> Result<DefenderStatus, String> {
    let text = stdout.trim();
    let raw: Raw = serde_json::from_str(text).map_err(|err| {
        let start: String = text.chars().take(200).collect();
        format!("Defender's state is not the JSON the script writes ({err}): {start:?}")
    })?;
    let mut notes = Vec::new();
    if let Some(why) = raw.status_error {
        notes.push(format!("Get-MpComputerStatus: {}", why.trim()));
    }
    let detections = match (raw.detections, raw.detections_error) {
        (_, Some(why)) => {
            notes.push(format!("Get-MpThreatDetection: {}", why.trim()));
            None
        }
        (None, None) => Some(Vec::new()),
        (Some(value), None) => {
            let items = match value {
                serde_json::Value::Array(items) => items,
                serde_json::Value::Null => Vec::new(),
                one => vec![one],
            };
            Some(
                items
                    .iter()
                    .map(|item| Detection {
                        threat: item.get("threat").and_then(|t| t.as_str()).unwrap_or("unnamed threat").to_owned(),
                        time: item.get("time").and_then(|t| t.as_str()).unwrap_or("an unknown time").to_owned(),
                        resources: strings(item.get("resources")),
                    })
                    .collect(),
            )
        }
    };
    Ok(DefenderStatus {
        tamper_protection: raw.tamper_protection,
        realtime: raw.realtime,
        antivirus: raw.antivirus,
        detections,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quiet_defender_with_tamper_protection_on_reads_as_such() {
        let status = parse(r#"{"tamper_protection":true,"realtime":false,"antivirus":true,"detections":[]}"#).unwrap();
        assert_eq!(status.tamper_protection, Some(true));
        assert_eq!(status.detections, Some(Vec::new()));
        assert_eq!(status.summary(), "Tamper Protection on, real-time protection off, antivirus on, no detections");
        assert!(status.guest_detections().is_empty());
    }

    #[test]
    fn a_quarantined_guest_is_named_among_the_detections() {
        let out = r#"{"tamper_protection":true,"realtime":true,"antivirus":true,"detections":[
            {"threat":"Trojan:Win32/Wacatac.B!ml","time":"12/02/2026 10:01:02","resources":["file:_C:\\Program Files\\Arena\\arena-guest.exe"]},
            {"threat":"PUA:Win32/Other","time":"12/01/2026 09:00:00","resources":"file:_C:\\Users\\Docker\\Downloads\\x.exe"}]}"#;
        let status = parse(out).unwrap();
        let list = status.detections.as_ref().unwrap();
        assert_eq!(list.len(), 2);
        assert_eq!(list[1].resources, vec![r"file:_C:\Users\Docker\Downloads\x.exe".to_owned()]);
        let guest = status.guest_detections();
        assert_eq!(guest.len(), 1);
        assert_eq!(guest[0].threat, "Trojan:Win32/Wacatac.B!ml");
        assert!(
            status.summary().contains("2 detection(s): Trojan:Win32/Wacatac.B!ml at 12/02/2026"),
            "{}",
            status.summary()
        );
    }

    #[test]
    fn defender_off_or_unreadable_is_unknown_with_the_reason() {
        let status = parse(r#"{"status_error":"Operation failed with the following error: 0x800106ba","detections_error":"The service is not running"}"#).unwrap();
        assert_eq!((status.tamper_protection, status.realtime, status.detections.clone()), (None, None, None));
        let summary = status.summary();
        assert!(summary.starts_with("Tamper Protection unknown, real-time protection unknown"), "{summary}");
        assert!(summary.contains("detections unknown") && summary.contains("0x800106ba"), "{summary}");
        // The stub has none at all.
        let absent = DefenderStatus::absent("the stub backend has no Defender");
        assert!(absent.summary().contains("unknown") && absent.summary().contains("the stub backend has no Defender"));
        // Output that is not the script's is an error that quotes it.
        let err = parse("Get-MpComputerStatus : The term is not recognized").unwrap_err();
        assert!(err.contains("not the JSON") && err.contains("not recognized"), "{err}");
    }
}
