//! Getters of upstream's `getters/fileexplorer.py` that look for a name in a
//! known folder. Upstream asks the guest for the folder's path
//! (`/documents_path`, `/desktop_path`); here the guest's known-folder list says.

use arena_shared::files::{FileKind, KnownFolder};

use super::{guest_join, GetterError, Params};
use crate::value::Fetched;
use crate::EvalContext;

/// `get_vm_folder_exists_in_documents`: whether `Documents\<folder_name>` is a directory.
pub(super) async fn vm_folder_exists_in_documents(
    ctx: &EvalContext,
    params: &Params<'_>,
) -> Result<Fetched, GetterError> {
    let name = params.string("folder_name")?;
    let documents = known_folder(ctx, params, KnownFolder::Documents).await?;
    is_kind(ctx, params, &guest_join(&documents, name), FileKind::Dir).await
}

/// `get_vm_file_exists_in_desktop`: whether `Desktop\<file_name>` is a file.
pub(super) async fn vm_file_exists_in_desktop(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let name = params.string("file_name")?;
    let desktop = known_folder(ctx, params, KnownFolder::Desktop).await?;
    is_kind(ctx, params, &guest_join(&desktop, name), FileKind::File).await
}

/// The guest path of a known folder.
///
/// # Errors
///
/// A failed call, or a guest that does not name the folder.
pub(crate) async fn known_folder(
    ctx: &EvalContext,
    params: &Params<'_>,
    folder: KnownFolder,
) -> Result<String, GetterError> {
    let folders = ctx.client.folders().await.map_err(|err| params.guest(err))?;
    folders
        .folders
        .into_iter()
        .find_map(|(known, path)| (known == folder).then_some(path))
        .ok_or_else(|| params.failed(format!("the guest does not report its {folder:?} folder")))
}

async fn is_kind(ctx: &EvalContext, params: &Params<'_>, path: &str, kind: FileKind) -> Result<Fetched, GetterError> {
    let exists = ctx.client.exists(path).await.map_err(|err| params.guest(err))?;
    Ok(Fetched::Bool(exists.exists && exists.kind == Some(kind)))
}
