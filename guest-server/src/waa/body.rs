//! Request bodies the way Flask hands them to upstream's views.
//!
//! - [`PyJson`]: `request.json`, a [`serde_json::Value`], with Flask's failures as
//!   upstream's catch-all renders them (415 for a non-JSON content type, 400 for
//!   malformed JSON, both answered with HTTP 500).
//! - [`Data`]: reading fields from that value with Python's dict semantics
//!   (`"k" in data`, `data["k"]`, `data.get("k")`), including the exceptions a
//!   non-object body raises.
//! - [`PyForm`]: `request.form` and `request.files`, from an urlencoded or a
//!   multipart body; any other content type gives an empty form, as in Werkzeug.
//!
//! Routes that ignore the body take none of these, so they never require one.

use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Request};
use axum::http::{header, HeaderMap, StatusCode};
use serde_json::Value;

use crate::error::WaaError;
use crate::waa::py;

/// Werkzeug's text for `request.json` on a body that is not declared JSON.
pub(crate) const UNSUPPORTED_MEDIA_TYPE: &str = "415 Unsupported Media Type: Did not attempt to load JSON data because the request Content-Type was not 'application/json'.";

/// Werkzeug's text for a body over the size limit.
const TOO_LARGE: &str = "413 Request Entity Too Large: The data value transmitted exceeds the capacity limit.";

/// `request.json`: the parsed body of a request declared `application/json` (or `+json`).
#[derive(Debug, Clone)]
pub(crate) struct PyJson(pub(crate) Value);

fn mime_type(headers: &HeaderMap) -> String {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .map(|v| v.split(';').next().unwrap_or("").trim().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Flask's `Request.is_json`.
fn is_json(mime: &str) -> bool {
    mime == "application/json" || (mime.starts_with("application/") && mime.ends_with("+json"))
}

async fn read_bytes<S: Send + Sync>(req: Request, state: &S) -> Result<Bytes, WaaError> {
    Bytes::from_request(req, state).await.map_err(|rejection| {
        if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
            WaaError::catch(TOO_LARGE)
        } else {
            WaaError::catch(format!("400 Bad Request: {}", rejection.body_text()))
        }
    })
}

impl<S: Send + Sync> FromRequest<S> for PyJson {
    type Rejection = WaaError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        if !is_json(&mime_type(req.headers())) {
            return Err(WaaError::catch(UNSUPPORTED_MEDIA_TYPE));
        }
        let bytes = read_bytes(req, state).await?;
        serde_json::from_slice(&bytes)
            .map(PyJson)
            .map_err(|err| WaaError::catch(format!("400 Bad Request: Failed to decode JSON object: {err}")))
    }
}

/// A JSON body read with Python's dict semantics.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Data<'a>(pub(crate) &'a Value);

impl<'a> Data<'a> {
    /// `key in data`.
    ///
    /// # Errors
    ///
    /// Python's `TypeError` for bodies that are not containers (`null`, numbers, booleans).
    pub(crate) fn contains(&self, key: &str) -> Result<bool, WaaError> {
        match self.0 {
            Value::Object(map) => Ok(map.contains_key(key)),
            Value::Array(items) => Ok(items.iter().any(|v| v.as_str() == Some(key))),
            Value::String(s) => Ok(s.contains(key)),
            other => Err(WaaError::catch(format!("argument of type '{}' is not iterable", py::type_name(other)))),
        }
    }

    /// `data[key]`.
    ///
    /// # Errors
    ///
    /// `KeyError` for a missing key, `TypeError` for a body that is not an object.
    pub(crate) fn index(&self, key: &str) -> Result<&'a Value, WaaError> {
        match self.0 {
            Value::Object(map) => map.get(key).ok_or_else(|| WaaError::catch(py::repr_str(key))),
            Value::Array(_) => Err(WaaError::catch("list indices must be integers or slices, not str")),
            Value::String(_) => Err(WaaError::catch("string indices must be integers")),
            other => Err(WaaError::catch(format!("'{}' object is not subscriptable", py::type_name(other)))),
        }
    }

    /// `data.get(key)`.
    ///
    /// # Errors
    ///
    /// `AttributeError` for a body that is not an object.
    pub(crate) fn get(&self, key: &str) -> Result<Option<&'a Value>, WaaError> {
        match self.0 {
            Value::Object(map) => Ok(map.get(key)),
            other => Err(WaaError::catch(format!("'{}' object has no attribute 'get'", py::type_name(other)))),
        }
    }

    /// `data[key]` after a successful `key in data`, for the common "required field" pattern:
    /// `Ok(None)` when the key is absent.
    ///
    /// # Errors
    ///
    /// As [`Data::contains`] and [`Data::index`].
    pub(crate) fn required(&self, key: &str) -> Result<Option<&'a Value>, WaaError> {
        if self.contains(key)? {
            self.index(key).map(Some)
        } else {
            Ok(None)
        }
    }

    /// `bool(data.get(key, False))`.
    ///
    /// # Errors
    ///
    /// As [`Data::get`].
    pub(crate) fn flag(&self, key: &str) -> Result<bool, WaaError> {
        Ok(self.get(key)?.is_some_and(arena_shared::cmdline::truthy))
    }
}

/// File parts up to this size stay in memory; larger ones are spooled to an unnamed
/// temporary file (Werkzeug spools above 500 KiB), so an upload's size costs disk, not RSS.
pub(crate) const SPOOL_ABOVE: usize = 1 << 20;

/// The content of an uploaded file part.
#[derive(Debug)]
pub(crate) enum FileData {
    Memory(Bytes),
    /// An unnamed temporary file (deleted by the OS when closed, even after a crash),
    /// positioned at its start.
    Spooled(std::fs::File),
}

impl FileData {
    /// Copies the whole content into `out`. Blocking: call it off the async runtime.
    pub(crate) fn copy_to(self, out: &mut impl std::io::Write) -> std::io::Result<u64> {
        match self {
            FileData::Memory(bytes) => out.write_all(&bytes).map(|()| bytes.len() as u64),
            FileData::Spooled(mut file) => std::io::copy(&mut file, out),
        }
    }
}

/// An uploaded file part of a multipart body.
#[derive(Debug)]
pub(crate) struct FormFile {
    pub(crate) name: String,
    pub(crate) data: FileData,
}

/// `request.form` and `request.files`.
#[derive(Debug, Default)]
pub(crate) struct PyForm {
    fields: Vec<(String, String)>,
    files: Vec<FormFile>,
}

impl PyForm {
    /// `request.form[name]`: the first value of a field.
    pub(crate) fn field(&self, name: &str) -> Option<&str> {
        self.fields.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    /// `request.files[name]`: the first file part of that name, taken out of the form.
    pub(crate) fn take_file(&mut self, name: &str) -> Option<FormFile> {
        let index = self.files.iter().position(|f| f.name == name)?;
        Some(self.files.swap_remove(index))
    }
}

impl<S: Send + Sync> FromRequest<S> for PyForm {
    type Rejection = WaaError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let mime = mime_type(req.headers());
        if mime == "multipart/form-data" {
            parse_multipart(req, state).await
        } else if mime == "application/x-www-form-urlencoded" {
            let bytes = read_bytes(req, state).await?;
            Ok(PyForm { fields: parse_urlencoded(&bytes), files: Vec::new() })
        } else {
            Ok(PyForm::default())
        }
    }
}

async fn parse_multipart<S: Send + Sync>(req: Request, state: &S) -> Result<PyForm, WaaError> {
    let mut form = PyForm::default();
    // Werkzeug parses forms silently: a malformed body (no boundary, a broken part)
    // leaves the form empty instead of failing the request.
    let Ok(mut multipart) = Multipart::from_request(req, state).await else {
        return Ok(form);
    };
    loop {
        match multipart.next_field().await {
            Ok(Some(field)) => {
                let name = field.name().unwrap_or_default().to_owned();
                if field.file_name().is_some() {
                    let data = match spool(field).await {
                        Ok(data) => data,
                        Err(Spool::Body(err)) => return multipart_failure(err),
                        Err(Spool::Disk(err)) => {
                            return Err(WaaError::catch(format!("could not spool the uploaded file: {err}")))
                        }
                    };
                    form.files.push(FormFile { name, data });
                } else {
                    let data = match field.bytes().await {
                        Ok(data) => data,
                        Err(err) => return multipart_failure(err),
                    };
                    form.fields.push((name, String::from_utf8_lossy(&data).into_owned()));
                }
            }
            Ok(None) => return Ok(form),
            Err(err) => return multipart_failure(err),
        }
    }
}

enum Spool {
    Body(axum::extract::multipart::MultipartError),
    Disk(std::io::Error),
}

/// Reads a file part chunk by chunk: in memory up to [`SPOOL_ABOVE`], then into an
/// unnamed temporary file written asynchronously.
async fn spool(mut field: axum::extract::multipart::Field<'_>) -> Result<FileData, Spool> {
    use tokio::io::AsyncWriteExt;
    let mut memory = Vec::new();
    let mut disk: Option<tokio::fs::File> = None;
    while let Some(chunk) = field.chunk().await.map_err(Spool::Body)? {
        if let Some(file) = disk.as_mut() {
            file.write_all(&chunk).await.map_err(Spool::Disk)?;
        } else if memory.len() + chunk.len() > SPOOL_ABOVE {
            let mut file = tokio::fs::File::from_std(tempfile::tempfile().map_err(Spool::Disk)?);
            file.write_all(&memory).await.map_err(Spool::Disk)?;
            file.write_all(&chunk).await.map_err(Spool::Disk)?;
            memory = Vec::new();
            disk = Some(file);
        } else {
            memory.extend_from_slice(&chunk);
        }
    }
    match disk {
        None => Ok(FileData::Memory(memory.into())),
        Some(mut file) => {
            use tokio::io::AsyncSeekExt;
            file.flush().await.map_err(Spool::Disk)?;
            file.rewind().await.map_err(Spool::Disk)?;
            Ok(FileData::Spooled(file.into_std().await))
        }
    }
}

fn multipart_failure(err: axum::extract::multipart::MultipartError) -> Result<PyForm, WaaError> {
    if err.status() == StatusCode::PAYLOAD_TOO_LARGE {
        return Err(WaaError::catch(TOO_LARGE));
    }
    tracing::debug!(error = %err, "malformed multipart body; treating the form as empty");
    Ok(PyForm::default())
}

/// Parses `application/x-www-form-urlencoded` pairs: `+` is a space, `%XX` a byte,
/// a pair without `=` has an empty value, and text is decoded as lossy UTF-8.
pub(crate) fn parse_urlencoded(body: &[u8]) -> Vec<(String, String)> {
    body.split(|b| *b == b'&')
        .filter(|pair| !pair.is_empty())
        .map(|pair| {
            let (key, value) = match pair.iter().position(|b| *b == b'=') {
                Some(i) => (&pair[..i], &pair[i + 1..]),
                None => (pair, &b""[..]),
            };
            (percent_decode(key), percent_decode(value))
        })
        .collect()
}

fn percent_decode(input: &[u8]) -> String {
    String::from_utf8_lossy(&crate::urlencoded::decode_bytes(input)).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn urlencoded_pairs_decode_like_werkzeug() {
        assert_eq!(
            parse_urlencoded(b"file_path=C%3A%5CUsers%5Ca+b.txt&flag&x=%zz&&y=%E2%9C%93"),
            vec![
                ("file_path".to_owned(), r"C:\Users\a b.txt".to_owned()),
                ("flag".to_owned(), String::new()),
                ("x".to_owned(), "%zz".to_owned()),
                ("y".to_owned(), "✓".to_owned()),
            ]
        );
    }

    #[test]
    fn data_follows_python_dict_semantics() {
        let obj = json!({"path": "a", "shell": "false", "n": 0});
        let data = Data(&obj);
        assert!(data.contains("path").unwrap());
        assert!(!data.contains("nope").unwrap());
        assert_eq!(data.required("path").unwrap(), Some(&json!("a")));
        assert_eq!(data.required("nope").unwrap(), None);
        assert!(data.flag("shell").unwrap());
        assert!(!data.flag("n").unwrap());
        assert!(!data.flag("missing").unwrap());

        let list = json!(["path"]);
        let message = |e: WaaError| match e {
            WaaError::Catch(m) => m,
            WaaError::Custom(_) => panic!("expected a catch-all error"),
        };
        assert!(Data(&list).contains("path").unwrap());
        assert_eq!(message(Data(&list).index("path").unwrap_err()), "list indices must be integers or slices, not str");
        assert_eq!(message(Data(&list).get("x").unwrap_err()), "'list' object has no attribute 'get'");
        assert_eq!(
            message(Data(&json!(null)).contains("x").unwrap_err()),
            "argument of type 'NoneType' is not iterable"
        );
        assert_eq!(message(Data(&obj).index("zz").unwrap_err()), "'zz'");
    }

    /// A multipart body with one text field and one file part of `size` bytes (under
    /// axum's default 2 MB body limit, which applies without the router's own).
    fn upload_request(size: usize) -> Request {
        let mut body =
            b"--XyZ\r\ncontent-disposition: form-data; name=\"file_data\"; filename=\"a.bin\"\r\n\r\n".to_vec();
        body.extend((0..size).map(|i| (i % 251) as u8));
        body.extend_from_slice(
            b"\r\n--XyZ\r\ncontent-disposition: form-data; name=\"file_path\"\r\n\r\nC:\\a.bin\r\n--XyZ--\r\n",
        );
        Request::builder()
            .method("POST")
            .header(header::CONTENT_TYPE, "multipart/form-data; boundary=XyZ")
            .body(axum::body::Body::from(body))
            .expect("request")
    }

    #[tokio::test]
    async fn file_parts_over_the_threshold_are_spooled_to_disk_and_read_back_whole() {
        for (size, spooled) in
            [(10, false), (SPOOL_ABOVE, false), (SPOOL_ABOVE + 1, true), (SPOOL_ABOVE + 300_007, true)]
        {
            let mut form = PyForm::from_request(upload_request(size), &()).await.expect("form");
            // The file part came first; the field after it is still read.
            assert_eq!(form.field("file_path"), Some(r"C:\a.bin"));
            let file = form.take_file("file_data").expect("file part");
            assert_eq!(matches!(file.data, FileData::Spooled(_)), spooled, "{size} bytes");
            let mut out = Vec::new();
            assert_eq!(file.data.copy_to(&mut out).expect("copy"), size as u64);
            assert!(out.iter().enumerate().all(|(i, b)| *b == (i % 251) as u8), "{size} bytes read back intact");
            assert!(form.take_file("file_data").is_none());
        }
    }
}
