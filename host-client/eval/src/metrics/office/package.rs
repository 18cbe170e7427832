//! An Office Open XML or OpenDocument package: a zip archive of XML parts,
//! read part by part, with the relationship (`_rels/*.rels`) lookup that ties
//! OOXML parts together.
//!
//! This is not a general zip tool: it reads UTF-8 XML parts of one file the
//! metrics were handed, and reports every failure as a [`MetricError`].

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use super::super::MetricError;

/// The largest part we inflate (256 MiB): a guard against zip bombs in files an agent produced.
const MAX_PART_BYTES: u64 = 256 * 1024 * 1024;

/// One opened package.
pub(super) struct Package {
    path: PathBuf,
    archive: zip::ZipArchive<File>,
}

impl std::fmt::Debug for Package {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Package").field("path", &self.path).finish_non_exhaustive()
    }
}

/// A relationship of a part: its id, type URI and the resolved target part name.
#[derive(Debug, Clone)]
pub(super) struct Rel {
    pub(super) id: String,
    pub(super) kind: String,
    pub(super) target: String,
}

/// The relationships of one part, in the order its `.rels` part lists them.
#[derive(Debug, Clone, Default)]
pub(super) struct Rels(Vec<Rel>);

impl Rels {
    /// The target of relationship `id`.
    pub(super) fn target(&self, id: &str) -> Option<&str> {
        self.0.iter().find(|rel| rel.id == id).map(|rel| rel.target.as_str())
    }

    /// The targets whose type URI ends with `/{kind}` (e.g. `drawing`, `pivotTable`), in order.
    pub(super) fn of_kind<'a>(&'a self, kind: &'a str) -> impl Iterator<Item = &'a str> + 'a {
        self.0.iter().filter(move |rel| rel.kind.rsplit('/').next() == Some(kind)).map(|rel| rel.target.as_str())
    }
}

impl Package {
    /// Opens `path` as a zip archive.
    ///
    /// # Errors
    ///
    /// [`MetricError::Io`] when unreadable, [`MetricError::Parse`] when not a zip.
    pub(super) fn open(path: &Path) -> Result<Package, MetricError> {
        let file = File::open(path).map_err(|source| MetricError::Io { path: path.to_owned(), source })?;
        let archive = zip::ZipArchive::new(file).map_err(|err| MetricError::Parse {
            what: path.display().to_string(),
            message: format!("not an Office document (zip): {err}"),
        })?;
        Ok(Package { path: path.to_owned(), archive })
    }

    /// A parse error about this package.
    pub(super) fn error(&self, message: impl Into<String>) -> MetricError {
        MetricError::Parse { what: self.path.display().to_string(), message: message.into() }
    }

    /// The text of part `name` (no leading slash), or `None` when the package has no such part.
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the part cannot be inflated or is not UTF-8.
    pub(super) fn part(&mut self, name: &str) -> Result<Option<String>, MetricError> {
        let name = name.trim_start_matches('/');
        let entry = match self.archive.by_name(name) {
            Ok(entry) => entry,
            Err(zip::result::ZipError::FileNotFound) => return Ok(None),
            Err(err) => {
                return Err(MetricError::Parse {
                    what: self.path.display().to_string(),
                    message: format!("{name}: {err}"),
                })
            }
        };
        let mut bytes = Vec::new();
        entry.take(MAX_PART_BYTES).read_to_end(&mut bytes).map_err(|err| MetricError::Parse {
            what: self.path.display().to_string(),
            message: format!("{name}: {err}"),
        })?;
        String::from_utf8(bytes).map(Some).map_err(|err| self.error(format!("{name} is not UTF-8: {err}")))
    }

    /// The text of part `name`, which the format requires.
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the part is missing or unreadable.
    pub(super) fn required(&mut self, name: &str) -> Result<String, MetricError> {
        self.part(name)?.ok_or_else(|| self.error(format!("the package has no {name}")))
    }

    /// The relationships of part `name` (none when it has no `.rels` part).
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the `.rels` part is not XML.
    pub(super) fn rels(&mut self, name: &str) -> Result<Rels, MetricError> {
        let name = name.trim_start_matches('/');
        let (dir, file) = name.rsplit_once('/').unwrap_or(("", name));
        let rels_name = if dir.is_empty() { format!("_rels/{file}.rels") } else { format!("{dir}/_rels/{file}.rels") };
        let Some(text) = self.part(&rels_name)? else { return Ok(Rels::default()) };
        let doc = parse_xml(&text).map_err(|err| self.error(format!("{rels_name}: {err}")))?;
        let mut rels = Vec::new();
        for node in doc.descendants().filter(|n| n.has_tag_name("Relationship")) {
            let (Some(id), Some(target)) = (node.attribute("Id"), node.attribute("Target")) else { continue };
            if node.attribute("TargetMode") == Some("External") {
                continue;
            }
            let kind = node.attribute("Type").unwrap_or_default().to_owned();
            rels.push(Rel { id: id.to_owned(), kind, target: resolve(dir, target) });
        }
        Ok(Rels(rels))
    }

    /// Parses part `name` as XML and hands the document to `f`.
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the part is missing or not XML.
    pub(super) fn with_xml<T>(
        &mut self,
        name: &str,
        f: impl FnOnce(&roxmltree::Document<'_>) -> Result<T, MetricError>,
    ) -> Result<T, MetricError> {
        let text = self.required(name)?;
        let doc = parse_xml(&text).map_err(|err| self.error(format!("{name}: {err}")))?;
        f(&doc)
    }
}

/// Parses XML with DTDs allowed (some producers emit a doctype; entities stay unexpanded beyond the defaults).
pub(super) fn parse_xml(text: &str) -> Result<roxmltree::Document<'_>, roxmltree::Error> {
    roxmltree::Document::parse_with_options(text, roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() })
}

/// Resolves a relationship target against the folder of its source part.
fn resolve(dir: &str, target: &str) -> String {
    let joined = if let Some(absolute) = target.strip_prefix('/') {
        absolute.to_owned()
    } else if dir.is_empty() {
        target.to_owned()
    } else {
        format!("{dir}/{target}")
    };
    let mut parts: Vec<&str> = Vec::new();
    for piece in joined.split('/') {
        match piece {
            "" | "." => {}
            ".." => {
                parts.pop();
            }
            other => parts.push(other),
        }
    }
    parts.join("/")
}

#[cfg(test)]
mod tests {
    use super::resolve;

    #[test]
    fn targets_resolve_against_the_source_folder() {
        assert_eq!(resolve("xl", "worksheets/sheet1.xml"), "xl/worksheets/sheet1.xml");
        assert_eq!(resolve("xl/worksheets", "../drawings/drawing1.xml"), "xl/drawings/drawing1.xml");
        assert_eq!(resolve("xl/worksheets", "/xl/pivotTables/p.xml"), "xl/pivotTables/p.xml");
        assert_eq!(resolve("", "word/document.xml"), "word/document.xml");
    }
}
