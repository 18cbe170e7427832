//! The screen a UEFI VM starts with: OVMF's `PlatformConfig` variable, written
//! into the VM's own copy of the UEFI variables before its first boot.
//!
//! Under OVMF, Windows drives QEMU's standard VGA with its basic display
//! driver, which keeps the mode the firmware's graphics output set (it cannot
//! change modes without a VBE BIOS): without this the screen stays at OVMF's
//! default, 800x600. OVMF's `PlatformDxe` reads the preferred resolution from
//! the non-volatile variable `PlatformConfig` (vendor GUID
//! `gOvmfPlatformConfigGuid` 7235c51c-0c80-4cab-87ac-3b084a6304b1, data two
//! little-endian `UINT32`s, horizontal then vertical; edk2's
//! `OvmfPkg/PlatformDxe/PlatformConfig.[ch]`) and sets the console's mode from
//! it. The mode must be one of the GOP modes of QEMU's video driver, which
//! lists the common sizes (1440x900 among them).
//!
//! The variables file is an edk2 firmware volume holding a variable store
//! (edk2's `VariableFormat.h`, `AuthenticatedVariableFormat.h`): a header whose
//! signature GUID says whether its variables carry the authenticated header (as
//! the secure-boot builds' and Debian's 4 MiB files do), then the variables, each
//! 4-byte aligned, then free space (0xFF). The variable is appended in the free
//! space in the store's own format; one already there is marked deleted first.

/// `gOvmfPlatformConfigGuid`, in its on-disk byte order.
const PLATFORM_CONFIG_GUID: [u8; 16] =
    guid(0x7235_c51c, 0x0c80, 0x4cab, [0x87, 0xac, 0x3b, 0x08, 0x4a, 0x63, 0x04, 0xb1]);
/// `gEfiAuthenticatedVariableGuid`: a store of authenticated variable headers.
const AUTHENTICATED_STORE: [u8; 16] =
    guid(0xaaf3_2c78, 0x947b, 0x439a, [0xa1, 0x80, 0x2e, 0x14, 0x4e, 0xc3, 0x77, 0x92]);
/// `gEfiVariableGuid`: a store of plain variable headers.
const PLAIN_STORE: [u8; 16] = guid(0xddcf_3616, 0x3275, 0x4164, [0x98, 0xb6, 0xfe, 0x85, 0x70, 0x7f, 0xfe, 0x7d]);

/// `EFI_VARIABLE_NON_VOLATILE | BOOTSERVICE_ACCESS | RUNTIME_ACCESS`, as `PlatformConfigSave` writes it.
const ATTRIBUTES: u32 = 0x7;
const START_ID: u16 = 0x55AA;
/// `VAR_ADDED`, and the bit cleared by `VAR_DELETED`.
const VAR_ADDED: u8 = 0x3F;
const VAR_DELETED_MASK: u8 = 0xFD;

const fn guid(a: u32, b: u16, c: u16, d: [u8; 8]) -> [u8; 16] {
    let a = a.to_le_bytes();
    let b = b.to_le_bytes();
    let c = c.to_le_bytes();
    [a[0], a[1], a[2], a[3], b[0], b[1], c[0], c[1], d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]]
}

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    bytes.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

fn u16_at(bytes: &[u8], at: usize) -> Option<u16> {
    bytes.get(at..at + 2).map(|b| u16::from_le_bytes([b[0], b[1]]))
}

const fn align4(n: usize) -> usize {
    (n + 3) & !3
}

/// Sets OVMF's preferred resolution in a variables file's bytes.
///
/// # Errors
///
/// The bytes are not an edk2 variables file, or its store has no room left.
pub fn set_resolution(vars: &mut [u8], width: u32, height: u32) -> Result<(), String> {
    // The firmware volume header: `_FVH` at 40, its length at 48.
    if vars.get(40..44) != Some(b"_FVH".as_slice()) {
        return Err("not an OVMF variables file (no firmware volume header)".into());
    }
    let store = usize::from(u16_at(vars, 48).ok_or("short file")?);
    let signature = vars.get(store..store + 16).ok_or("short file")?;
    let authenticated = if signature == AUTHENTICATED_STORE {
        true
    } else if signature == PLAIN_STORE {
        false
    } else {
        return Err("the firmware volume holds no variable store".into());
    };
    let store_size = u32_at(vars, store + 16).ok_or("short file")? as usize;
    let end = (store + store_size).min(vars.len());
    // Header: StartId, State, Reserved, Attributes, [MonotonicCount, TimeStamp, PubKeyIndex],
    // NameSize, DataSize, VendorGuid.
    let header = if authenticated { 60 } else { 32 };
    let (name_size_at, data_size_at, guid_at) = if authenticated { (36, 40, 44) } else { (8, 12, 16) };
    let name: Vec<u8> = "PlatformConfig\0".encode_utf16().flat_map(u16::to_le_bytes).collect();
    let mut at = align4(store + 28);
    while u16_at(vars, at) == Some(START_ID) {
        let name_size = u32_at(vars, at + name_size_at).ok_or("short file")? as usize;
        let data_size = u32_at(vars, at + data_size_at).ok_or("short file")? as usize;
        let this_name = vars.get(at + header..at + header + name_size).unwrap_or_default();
        let this_guid = vars.get(at + guid_at..at + guid_at + 16).unwrap_or_default();
        if vars.get(at + 2) == Some(&VAR_ADDED) && this_guid == PLATFORM_CONFIG_GUID && this_name == name.as_slice() {
            vars[at + 2] &= VAR_DELETED_MASK;
        }
        at = align4(at + header + name_size + data_size);
    }
    let mut data = width.to_le_bytes().to_vec();
    data.extend(height.to_le_bytes());
    let total = header + name.len() + data.len();
    if at + total > end || vars[at..at + total].iter().any(|b| *b != 0xFF) {
        return Err("the variable store has no free room for PlatformConfig".into());
    }
    let mut record = vec![0u8; header];
    record[..2].copy_from_slice(&START_ID.to_le_bytes());
    record[2] = VAR_ADDED;
    record[4..8].copy_from_slice(&ATTRIBUTES.to_le_bytes());
    record[name_size_at..name_size_at + 4].copy_from_slice(&(name.len() as u32).to_le_bytes());
    record[data_size_at..data_size_at + 4].copy_from_slice(&(data.len() as u32).to_le_bytes());
    record[guid_at..guid_at + 16].copy_from_slice(&PLATFORM_CONFIG_GUID);
    record.extend(&name);
    record.extend(&data);
    vars[at..at + total].copy_from_slice(&record);
    Ok(())
}

/// The resolution a variables file's bytes hold, if any.
pub fn resolution(vars: &[u8]) -> Option<(u32, u32)> {
    let store = usize::from(u16_at(vars, 48)?);
    let authenticated = vars.get(store..store + 16)? == AUTHENTICATED_STORE;
    let header = if authenticated { 60 } else { 32 };
    let (name_size_at, data_size_at, guid_at) = if authenticated { (36, 40, 44) } else { (8, 12, 16) };
    let mut at = align4(store + 28);
    let mut found = None;
    while u16_at(vars, at) == Some(START_ID) {
        let name_size = u32_at(vars, at + name_size_at)? as usize;
        let data_size = u32_at(vars, at + data_size_at)? as usize;
        if *vars.get(at + 2)? == VAR_ADDED && vars.get(at + guid_at..at + guid_at + 16)? == PLATFORM_CONFIG_GUID {
            let data = at + header + name_size;
            found = Some((u32_at(vars, data)?, u32_at(vars, data + 4)?));
        }
        at = align4(at + header + name_size + data_size);
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Debian's files when the ovmf package is installed (the UEFI VM tests need them too).
    fn debian_vars() -> Vec<(String, Vec<u8>)> {
        ["/usr/share/OVMF/OVMF_VARS_4M.fd", "/usr/share/OVMF/OVMF_VARS_4M.ms.fd", "/usr/share/OVMF/OVMF_VARS.fd"]
            .iter()
            .filter_map(|p| std::fs::read(p).ok().map(|b| ((*p).to_owned(), b)))
            .collect()
    }

    #[test]
    fn the_resolution_is_written_read_back_and_replaced() {
        let files = debian_vars();
        if files.is_empty() {
            arena_test_support::skip(
                "the_resolution_is_written_read_back_and_replaced",
                "Debian's ovmf is not installed",
                "ARENA_REQUIRE_QEMU",
            );
            return;
        }
        for (path, original) in files {
            let mut vars = original.clone();
            assert_eq!(resolution(&vars), None, "{path}");
            set_resolution(&mut vars, 1440, 900).unwrap();
            assert_eq!(resolution(&vars), Some((1440, 900)), "{path}");
            set_resolution(&mut vars, 1920, 1080).unwrap();
            assert_eq!(resolution(&vars), Some((1920, 1080)), "{path}");
            // Only free space changed, besides the old copy's state byte.
            let changed = vars.iter().zip(&original).filter(|(a, b)| a != b).count();
            assert!(changed < 200, "{path}: {changed}");
        }
    }

    #[test]
    fn what_is_not_a_variables_file_is_refused() {
        assert!(set_resolution(&mut [0u8; 4096], 1440, 900).unwrap_err().contains("not an OVMF variables file"));
        let mut fake = vec![0u8; 4096];
        fake[40..44].copy_from_slice(b"_FVH");
        fake[48] = 0x48;
        assert!(set_resolution(&mut fake, 1440, 900).unwrap_err().contains("no variable store"));
    }
}
