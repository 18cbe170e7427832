//! The stub's in-memory registry: keys and value names are case-insensitive and
//! hive names fold onto their short forms (`HKEY_CURRENT_USER` is `HKCU`), as on Windows.
//!
//! It models values only; there are no security descriptors, links or volatile keys.
//! Keys form a tree, each holding its own name, so a key's memory is linear in its
//! path's length (storing every ancestor's full path made a 510-level key of 128 KB
//! cost 63 MB).

use std::collections::BTreeMap;

use arena_shared::registry::RegistryValue;

use crate::desktop::{DesktopError, DesktopResult};

/// Where the wallpaper path lives.
pub(crate) const DESKTOP_KEY: &str = r"HKCU\Control Panel\Desktop";
/// The value holding the wallpaper path.
pub(crate) const WALLPAPER_VALUE: &str = "Wallpaper";

const HIVES: &[(&str, &str)] = &[
    ("hkey_current_user", "HKCU"),
    ("hkcu", "HKCU"),
    ("hkey_local_machine", "HKLM"),
    ("hklm", "HKLM"),
    ("hkey_classes_root", "HKCR"),
    ("hkcr", "HKCR"),
    ("hkey_users", "HKU"),
    ("hku", "HKU"),
    ("hkey_current_config", "HKCC"),
    ("hkcc", "HKCC"),
];

/// A key path folded to its comparison form (`hkcu\control panel\desktop`) and its display form.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct KeyPath {
    pub(crate) folded: String,
    pub(crate) display: String,
}

/// Normalises a key path: hive alias folded, separators single, no leading or trailing `\`.
///
/// # Errors
///
/// A message naming the key for an empty path or an unknown hive.
pub(crate) fn normalize_key(key: &str) -> Result<KeyPath, String> {
    crate::desktop::windows::winsys::check_registry_limits(key, None)?;
    let mut parts = key.split('\\').filter(|p| !p.is_empty());
    let Some(hive) = parts.next() else {
        return Err(format!("registry key {key:?} is empty"));
    };
    let hive_lower = hive.to_lowercase();
    let Some((_, short)) = HIVES.iter().find(|(name, _)| *name == hive_lower) else {
        return Err(format!("registry key {key:?} does not start with a hive (HKCU, HKLM, HKCR, HKU or HKCC)"));
    };
    let mut display = (*short).to_owned();
    for part in parts {
        display.push('\\');
        display.push_str(part);
    }
    Ok(KeyPath { folded: display.to_lowercase(), display })
}

#[derive(Debug, Default)]
struct Key {
    /// The key's own name as first written.
    name: String,
    /// Folded value name -> (name as written, data). The default value is the empty name.
    values: BTreeMap<String, (String, RegistryValue)>,
    /// Folded subkey name -> subkey.
    children: BTreeMap<String, Key>,
}

/// The registry.
#[derive(Debug, Default)]
pub(crate) struct Registry {
    /// Short hive name (`HKCU`) -> its root key.
    hives: BTreeMap<String, Key>,
}

impl Registry {
    /// A registry with the keys every Windows desktop has.
    pub(crate) fn seeded() -> Registry {
        let mut reg = Registry::default();
        let defaults: &[(&str, &str, RegistryValue)] = &[
            (DESKTOP_KEY, WALLPAPER_VALUE, RegistryValue::String(String::new())),
            (DESKTOP_KEY, "WallpaperStyle", RegistryValue::String("10".into())),
            (DESKTOP_KEY, "TileWallpaper", RegistryValue::String("0".into())),
            (r"HKCU\Control Panel\International", "sShortDate", RegistryValue::String("M/d/yyyy".into())),
            (
                r"HKCU\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced",
                "HideFileExt",
                RegistryValue::Dword(1),
            ),
            (r"HKCU\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced", "Hidden", RegistryValue::Dword(2)),
            (
                r"HKCU\Software\Microsoft\Windows\CurrentVersion\Themes\Personalize",
                "AppsUseLightTheme",
                RegistryValue::Dword(1),
            ),
            (
                r"HKCU\Software\Microsoft\Windows\CurrentVersion\Themes\Personalize",
                "SystemUsesLightTheme",
                RegistryValue::Dword(1),
            ),
            (
                r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion",
                "ProductName",
                RegistryValue::String("Windows 10 Enterprise".into()),
            ),
            // Windows 11 23H2's version numbers, which `platform.version()` prints as 10.0.22631.
            (
                r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion",
                "CurrentMajorVersionNumber",
                RegistryValue::Dword(10),
            ),
            (
                r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion",
                "CurrentMinorVersionNumber",
                RegistryValue::Dword(0),
            ),
            (
                r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion",
                "CurrentBuildNumber",
                RegistryValue::String("22631".into()),
            ),
            (
                r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion",
                "CurrentBuild",
                RegistryValue::String("22631".into()),
            ),
            (
                r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion",
                "DisplayVersion",
                RegistryValue::String("23H2".into()),
            ),
        ];
        for (key, value, data) in defaults {
            // The built-in keys are well-formed, so this cannot fail.
            let _ = reg.write(key, Some(value), data);
        }
        reg
    }

    /// The key at `path` and its display path as first written, if it exists.
    fn find(&self, path: &KeyPath) -> Option<(&Key, String)> {
        let mut parts = path.display.split('\\');
        let mut key = self.hives.get(parts.next()?)?;
        let mut display = key.name.clone();
        for part in parts {
            key = key.children.get(&part.to_lowercase())?;
            display.push('\\');
            display.push_str(&key.name);
        }
        Some((key, display))
    }

    /// Reads a value; `None` is the default value.
    ///
    /// # Errors
    ///
    /// [`DesktopError::InvalidInput`] for a malformed key, [`DesktopError::NotFound`]
    /// naming the key or the value when either is missing.
    pub(crate) fn read(&self, key: &str, value: Option<&str>) -> DesktopResult<RegistryValue> {
        let path = normalize_key(key).map_err(DesktopError::InvalidInput)?;
        let Some((entry, display)) = self.find(&path) else {
            return Err(DesktopError::NotFound(format!(
                "registry key {} not found",
                crate::error::clip(&path.display)
            )));
        };
        let name = value.unwrap_or("");
        match entry.values.get(&name.to_lowercase()) {
            Some((_, data)) => Ok(data.clone()),
            None if name.is_empty() => Err(DesktopError::NotFound(format!(
                "registry key {} has no default value",
                crate::error::clip(&display)
            ))),
            None => Err(DesktopError::NotFound(format!(
                "registry value {:?} not found in {}",
                crate::error::clip(name),
                crate::error::clip(&display)
            ))),
        }
    }

    /// Writes a value, creating the key and its parents.
    ///
    /// # Errors
    ///
    /// [`DesktopError::InvalidInput`] for a malformed key or [`RegistryValue::Unknown`] data.
    pub(crate) fn write(&mut self, key: &str, value: Option<&str>, data: &RegistryValue) -> DesktopResult<()> {
        let path = normalize_key(key).map_err(DesktopError::InvalidInput)?;
        if *data == RegistryValue::Unknown {
            return Err(DesktopError::InvalidInput(format!(
                "cannot write a value of unknown type to {}",
                crate::error::clip(&path.display)
            )));
        }
        // Creating a key creates its missing parents, as RegCreateKeyEx does.
        let mut parts = path.display.split('\\');
        let hive = parts.next().unwrap_or_default();
        let mut entry =
            self.hives.entry(hive.to_owned()).or_insert_with(|| Key { name: hive.to_owned(), ..Key::default() });
        for part in parts {
            entry = entry
                .children
                .entry(part.to_lowercase())
                .or_insert_with(|| Key { name: part.to_owned(), ..Key::default() });
        }
        let name = value.unwrap_or("").to_owned();
        entry.values.insert(name.to_lowercase(), (name, data.clone()));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_fold_hives_and_case() {
        let check =
            |input: &str, expected: &str| assert_eq!(normalize_key(input).unwrap().display, expected, "{input}");
        check(r"HKEY_CURRENT_USER\Control Panel\Desktop", r"HKCU\Control Panel\Desktop");
        check(r"hkcu\\Software\\", r"HKCU\Software");
        check(r"HKEY_LOCAL_MACHINE\SOFTWARE", r"HKLM\SOFTWARE");
        check(r"HKEY_CLASSES_ROOT\.txt", r"HKCR\.txt");
        check(r"HKEY_USERS\.DEFAULT", r"HKU\.DEFAULT");
        assert!(normalize_key(r"HKXX\a").unwrap_err().contains("HKXX"));
        assert!(normalize_key("").is_err());
    }

    #[test]
    fn values_read_back_case_insensitively() {
        let mut reg = Registry::seeded();
        reg.write(r"HKEY_CURRENT_USER\Software\Arena", Some("Count"), &RegistryValue::Dword(7)).unwrap();
        assert_eq!(reg.read(r"hkcu\software\arena", Some("COUNT")).unwrap(), RegistryValue::Dword(7));
        reg.write(r"HKCU\Software\Arena", None, &RegistryValue::String("dflt".into())).unwrap();
        assert_eq!(reg.read(r"HKCU\Software\Arena", None).unwrap(), RegistryValue::String("dflt".into()));
        // The parent was created along the way, without a default value.
        assert!(matches!(reg.read(r"HKCU\Software", None), Err(DesktopError::NotFound(m)) if m.contains("default")));
        assert_eq!(reg.read(DESKTOP_KEY, Some(WALLPAPER_VALUE)).unwrap(), RegistryValue::String(String::new()));
    }

    #[test]
    fn missing_keys_and_values_are_named() {
        let reg = Registry::seeded();
        assert!(
            matches!(reg.read(r"HKCU\Nope", Some("x")), Err(DesktopError::NotFound(m)) if m.contains(r"HKCU\Nope"))
        );
        assert!(matches!(reg.read(DESKTOP_KEY, Some("Nope")), Err(DesktopError::NotFound(m)) if m.contains("Nope")));
        assert!(matches!(reg.read(r"Bad\Key", None), Err(DesktopError::InvalidInput(_))));
        let mut reg = reg;
        assert!(matches!(reg.write(r"HKCU\x", None, &RegistryValue::Unknown), Err(DesktopError::InvalidInput(_))));
    }

    #[test]
    fn a_deep_key_is_stored_once_and_keeps_its_spelling() {
        let mut reg = Registry::seeded();
        reg.write(r"HKCU\Software\Deep\A\b", Some("v"), &RegistryValue::Dword(1)).unwrap();
        assert!(matches!(
            reg.read(r"hkcu\software\DEEP\a\B", None),
            Err(DesktopError::NotFound(m)) if m.contains(r"HKCU\Software\Deep\A\b")
        ));
        // Every level holds its own name only: the names stored add up to the path.
        let stored = |reg: &Registry| {
            fn walk(key: &Key) -> usize {
                key.name.len() + key.children.values().map(walk).sum::<usize>()
            }
            reg.hives.values().map(walk).sum::<usize>()
        };
        let before = stored(&reg);
        let level = "k".repeat(250);
        let key = format!("HKCU\\{}", vec![level.as_str(); 500].join("\\"));
        reg.write(&key, Some("v"), &RegistryValue::Dword(1)).unwrap();
        assert_eq!(stored(&reg) - before, 500 * 250, "linear in the key's length");
    }
}
