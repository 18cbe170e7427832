//! Getters that read the desktop's state: the foreground window's title
//! (upstream runs `pyautogui.getActiveWindowTitle()` in the guest's Python)
//! and the wallpaper image (upstream's `/wallpaper` route).

use arena_shared::registry::RegistryValue;

use super::{dest_path, GetterError, Params};
use crate::value::Fetched;
use crate::EvalContext;

/// Where Windows keeps the wallpaper path (what `SPI_GETDESKWALLPAPER` reads).
const DESKTOP_KEY: &str = r"HKCU\Control Panel\Desktop";
const WALLPAPER_VALUE: &str = "Wallpaper";

/// `get_vm_active_window_title`: the foreground window's title, stripped;
/// an empty string when no window has the focus (as pyautogui reports it).
pub(super) async fn vm_active_window_title(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let windows = ctx.client.windows().await.map_err(|err| params.guest(err))?;
    let title = windows.iter().find(|w| w.focused).map(|w| w.title.trim().to_owned()).unwrap_or_default();
    Ok(Fetched::Text(title))
}

/// `get_vm_wallpaper`: saves the wallpaper image to `dest` and returns its path.
/// No wallpaper is an error (upstream fails writing `None` to the file).
pub(super) async fn vm_wallpaper(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let local = dest_path(ctx, params, params.string("dest")?)?;
    let read = ctx.client.registry_get(DESKTOP_KEY, Some(WALLPAPER_VALUE)).await.map_err(|err| params.guest(err))?;
    let guest_path = match read.data {
        RegistryValue::String(path) if !path.trim().is_empty() => path,
        _ => return Err(params.failed("the guest has no wallpaper set")),
    };
    let file = ctx.client.pull_file(&guest_path).await.map_err(|err| params.guest(err))?;
    std::fs::write(&local, &file.bytes).map_err(|err| params.io(&local, err))?;
    Ok(Fetched::File(local))
}
