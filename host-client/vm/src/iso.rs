//! What a Windows installer ISO holds: the images of its `sources\install.wim`
//! (or `install.esd`), with index, name and edition, for `--list-editions` and
//! for choosing the image `--edition` names.
//!
//! Windows ISOs keep their files in UDF (the ISO 9660 side holds only a
//! README), read here with the `isomage` crate. A WIM file, and an ESD (the
//! same container, LZMS-compressed), begins with a 208-byte header whose
//! resource entry at offset 72 gives the offset and size of the image list, an
//! uncompressed UTF-16 XML document (Microsoft's "Windows Imaging File Format"
//! white paper, `WIMHEADER_V1_PACKED` and `RESHDR_DISK_SHORT`). From that XML
//! each `IMAGE` gives `INDEX`, `NAME`, `DISPLAYNAME`, `WINDOWS/EDITIONID` and
//! `WINDOWS/LANGUAGES/DEFAULT` (the image's default language, checked against
//! `--locale` by [`check_locale`]).
//!
//! `isomage` gives a file as one run of bytes on the disc; Windows ISOs (made
//! by `oscdimg`) store files contiguously, and a list that does not parse is an
//! error that says the ISO could not be read, never a wrong list.

use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// One image of `install.wim`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IsoImage {
    /// 1-based, as `/IMAGE/INDEX` takes it.
    pub index: u32,
    /// `NAME` ("Windows 11 Pro"; some Windows 11 media say "Windows 10 Pro").
    pub name: String,
    /// `DISPLAYNAME`, when the image has one.
    pub display_name: Option<String>,
    /// `WINDOWS/EDITIONID` ("Professional", "Core", "Enterprise").
    pub edition_id: Option<String>,
    /// `WINDOWS/LANGUAGES/DEFAULT` ("en-US"), when the list says it.
    pub default_language: Option<String>,
}

/// Longest image list read (real ones are a few tens of KiB).
const MAX_XML: u64 = 16 << 20;

/// The images of the installer at `path`: an ISO (UDF) holding
/// `sources/install.wim` or `sources/install.esd`, or such a WIM/ESD file itself.
///
/// # Errors
///
/// The file cannot be read, is neither, or its image list does not parse; the
/// message says which.
pub fn list_images(path: &Path) -> Result<Vec<IsoImage>, String> {
    let mut file = std::fs::File::open(path).map_err(|err| format!("{}: {err}", path.display()))?;
    let mut magic = [0u8; 8];
    if file.read_exact(&mut magic).is_ok() && &magic == WIM_MAGIC {
        return read_wim(&mut file, 0).map_err(|err| format!("{}: {err}", path.display()));
    }
    let root = isomage::udf::parse_udf(&mut file)
        .map_err(|err| format!("{}: not a UDF disc (a Windows ISO keeps its files in UDF): {err}", path.display()))?;
    let sources = root
        .children
        .iter()
        .find(|c| c.is_directory && c.name.eq_ignore_ascii_case("sources"))
        .ok_or_else(|| format!("{}: no sources folder: not a Windows installer ISO", path.display()))?;
    let wim = sources
        .children
        .iter()
        .find(|c| {
            !c.is_directory
                && (c.name.eq_ignore_ascii_case("install.wim") || c.name.eq_ignore_ascii_case("install.esd"))
        })
        .ok_or_else(|| {
            format!("{}: sources holds no install.wim or install.esd (a split install.swm is not read)", path.display())
        })?;
    let location = wim
        .file_location
        .ok_or_else(|| format!("{}: the disc does not say where sources/{} is", path.display(), wim.name))?;
    read_wim(&mut file, location).map_err(|err| format!("{} (sources/{}): {err}", path.display(), wim.name))
}

const WIM_MAGIC: &[u8; 8] = b"MSWIM\0\0\0";

/// Reads the image list of the WIM that starts at byte `start` of `file`.
fn read_wim(file: &mut (impl Read + Seek), start: u64) -> Result<Vec<IsoImage>, String> {
    let mut header = [0u8; 208];
    file.seek(SeekFrom::Start(start)).map_err(|err| err.to_string())?;
    file.read_exact(&mut header).map_err(|err| format!("reading the WIM header: {err}"))?;
    if &header[..8] != WIM_MAGIC {
        return Err("not a WIM file (no MSWIM header)".into());
    }
    // The XML data's resource entry: 7 bytes of stored size and a flags byte,
    // the offset, then the original size.
    let entry = &header[72..96];
    let flags = entry[7];
    let offset = u64::from_le_bytes(entry[8..16].try_into().map_err(|_| "short header")?);
    let size = u64::from_le_bytes(entry[16..24].try_into().map_err(|_| "short header")?);
    // RESHDR_FLAG_COMPRESSED: the image list is never compressed in WIMs Setup reads.
    if flags & 0x04 != 0 {
        return Err("the image list is compressed, which Windows media never do".into());
    }
    if size == 0 || size > MAX_XML || size % 2 != 0 {
        return Err(format!("the image list's size ({size} bytes) is not that of a UTF-16 document"));
    }
    let mut raw = vec![0u8; usize::try_from(size).map_err(|_| "too large")?];
    file.seek(SeekFrom::Start(start + offset)).map_err(|err| err.to_string())?;
    file.read_exact(&mut raw).map_err(|err| format!("reading the image list: {err}"))?;
    let units: Vec<u16> = raw.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
    let text = String::from_utf16(&units).map_err(|_| "the image list is not UTF-16".to_owned())?;
    parse_image_list(text.trim_start_matches('\u{feff}'))
}

/// The images of a WIM's XML image list (`<WIM><IMAGE INDEX="1">...`).
///
/// # Errors
///
/// Not XML, or an image without a usable index.
pub fn parse_image_list(xml: &str) -> Result<Vec<IsoImage>, String> {
    let doc = roxmltree::Document::parse(xml).map_err(|err| format!("the image list is not XML: {err}"))?;
    let child_text = |node: roxmltree::Node<'_, '_>, name: &str| {
        node.children().find(|c| c.has_tag_name(name)).and_then(|c| c.text()).map(|t| t.trim().to_owned())
    };
    let mut images = Vec::new();
    for image in doc.root_element().children().filter(|n| n.has_tag_name("IMAGE")) {
        let index: u32 = image
            .attribute("INDEX")
            .and_then(|i| i.trim().parse().ok())
            .filter(|i| *i > 0)
            .ok_or("an IMAGE without a valid INDEX")?;
        let windows = image.children().find(|c| c.has_tag_name("WINDOWS"));
        let edition_id = windows.and_then(|w| child_text(w, "EDITIONID"));
        let default_language = windows
            .and_then(|w| w.children().find(|c| c.has_tag_name("LANGUAGES")))
            .and_then(|l| child_text(l, "DEFAULT"))
            .filter(|d| !d.is_empty());
        images.push(IsoImage {
            index,
            name: child_text(image, "NAME").unwrap_or_default(),
            display_name: child_text(image, "DISPLAYNAME").filter(|d| !d.is_empty()),
            edition_id,
            default_language,
        });
    }
    images.sort_by_key(|i| i.index);
    if images.is_empty() {
        return Err("the image list names no image".into());
    }
    Ok(images)
}

/// Checks `--locale` against the installer's default language. The answer
/// file's windowsPE `UILanguage` (Microsoft's unattend reference,
/// Microsoft-Windows-International-Core-WinPE) must be a language the media
/// hold; one they do not leaves Setup at its language page, waiting for a
/// person, until the stage's deadline. `None` languages (a list that does not
/// say) pass: nothing is known to compare.
///
/// # Errors
///
/// The media's default languages, `--locale`, and the ways out.
pub fn check_locale(images: &[IsoImage], locale: &str) -> Result<(), String> {
    let mut languages: Vec<&str> = images.iter().filter_map(|i| i.default_language.as_deref()).collect();
    languages.sort_unstable();
    languages.dedup();
    if languages.is_empty() || languages.iter().any(|l| l.eq_ignore_ascii_case(locale)) {
        return Ok(());
    }
    Err(format!(
        "--locale {locale}: the installer's default language is {}, and Windows Setup stops at its language page for a language its media do not hold; use --locale {}, an ISO in {locale}, or --force-locale to go on anyway",
        languages.join(", "),
        languages[0]
    ))
}

/// The images as `--list-editions` prints them: index, name, edition.
pub fn render_list(images: &[IsoImage]) -> String {
    let mut out = String::from("index  edition                   name\n");
    for image in images {
        let name = match &image.display_name {
            Some(display) if *display != image.name => format!("{} ({display})", image.name),
            _ => image.name.clone(),
        };
        out.push_str(&format!("{:>5}  {:<24}  {name}\n", image.index, image.edition_id.as_deref().unwrap_or("?")));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIST: &str = r#"<WIM><TOTALBYTES>1</TOTALBYTES>
        <IMAGE INDEX="2"><NAME>Windows 10 Pro</NAME><DISPLAYNAME>Windows 11 Pro</DISPLAYNAME>
          <WINDOWS><EDITIONID>Professional</EDITIONID></WINDOWS></IMAGE>
        <IMAGE INDEX="1"><NAME>Windows 11 Home</NAME><WINDOWS><EDITIONID>Core</EDITIONID></WINDOWS></IMAGE>
    </WIM>"#;

    /// A WIM as Windows media carry it: the header, then (here, at once) the
    /// UTF-16 image list its resource entry points at.
    fn wim_bytes(xml: &str) -> Vec<u8> {
        let list: Vec<u8> = std::iter::once(0xfeffu16).chain(xml.encode_utf16()).flat_map(u16::to_le_bytes).collect();
        let mut header = vec![0u8; 208];
        header[..8].copy_from_slice(WIM_MAGIC);
        header[8..12].copy_from_slice(&208u32.to_le_bytes());
        header[72..79].copy_from_slice(&(list.len() as u64).to_le_bytes()[..7]);
        header[80..88].copy_from_slice(&208u64.to_le_bytes());
        header[88..96].copy_from_slice(&(list.len() as u64).to_le_bytes());
        header.extend(list);
        header
    }

    #[test]
    fn a_wim_file_lists_its_images_by_index_with_their_editions() {
        let dir = tempfile::tempdir().unwrap();
        let wim = dir.path().join("install.wim");
        std::fs::write(&wim, wim_bytes(LIST)).unwrap();
        let images = list_images(&wim).unwrap();
        assert_eq!(images.len(), 2);
        assert_eq!((images[0].index, images[0].edition_id.as_deref()), (1, Some("Core")));
        assert_eq!(images[1].name, "Windows 10 Pro");
        assert_eq!(images[1].display_name.as_deref(), Some("Windows 11 Pro"));
        let text = render_list(&images);
        assert!(text.contains("    2  Professional              Windows 10 Pro (Windows 11 Pro)"), "{text}");
    }

    #[test]
    fn the_default_language_is_read_and_checked_against_the_locale() {
        let xml = r#"<WIM><IMAGE INDEX="1"><NAME>Windows 11 Pro</NAME><WINDOWS><EDITIONID>Professional</EDITIONID>
            <LANGUAGES><LANGUAGE>de-DE</LANGUAGE><DEFAULT>de-DE</DEFAULT></LANGUAGES></WINDOWS></IMAGE></WIM>"#;
        let images = parse_image_list(xml).unwrap();
        assert_eq!(images[0].default_language.as_deref(), Some("de-DE"));
        check_locale(&images, "de-DE").unwrap();
        check_locale(&images, "de-de").unwrap();
        let err = check_locale(&images, "en-US").unwrap_err();
        assert!(
            err.contains("--locale en-US")
                && err.contains("default language is de-DE")
                && err.contains("--locale de-DE"),
            "{err}"
        );
        assert!(err.contains("--force-locale"), "{err}");
        // A list that does not say its language: nothing to compare.
        let silent = parse_image_list(LIST).unwrap();
        assert_eq!(silent[0].default_language, None);
        check_locale(&silent, "en-US").unwrap();
    }

    #[test]
    fn what_is_not_an_installer_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let junk = dir.path().join("x.iso");
        std::fs::write(&junk, b"not really an ISO").unwrap();
        let err = list_images(&junk).unwrap_err();
        assert!(err.contains("not a UDF disc"), "{err}");
        let mut compressed = wim_bytes(LIST);
        compressed[79] = 0x04;
        std::fs::write(&junk, &compressed).unwrap();
        assert!(list_images(&junk).unwrap_err().contains("compressed"));
        assert!(parse_image_list("<WIM/>").unwrap_err().contains("no image"));
        assert!(parse_image_list("<WIM><IMAGE INDEX=\"x\"/></WIM>").unwrap_err().contains("INDEX"));
    }
}
