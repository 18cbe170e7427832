//! Which windows and which title the model is shown: one rule for every observation,
//! the script host's `window_titles` and the WAA routes.
//!
//! Upstream's guest builds the list in `WindowManager.find_open_applications`
//! (`vm/setup/server/computer.py` at 6d39ed88): every window `pygetwindow.getAllWindows()`
//! enumerates (top-level windows, topmost first) that `IsWindowVisible` reports visible
//! and whose title is not empty, each title once, in first-seen order. A minimised window
//! is still visible in that sense, so it is listed.
//! Its observation's title (`obs_winagent` in `server/main.py`) is the foreground window's
//! title, or `Desktop` when that title is `Program Manager` (the desktop itself) or empty.

use crate::observation::WindowInfo;

/// The title of the window Windows uses for the desktop itself.
pub const PROGRAM_MANAGER: &str = "Program Manager";

/// What upstream calls the foreground when the desktop, or an untitled window, is in front.
pub const DESKTOP_TITLE: &str = "Desktop";

/// The titles upstream lists: visible (minimised included), non-empty, de-duplicated,
/// topmost first.
pub fn window_names(windows: &[WindowInfo]) -> Vec<String> {
    let mut ordered: Vec<&WindowInfo> = windows.iter().collect();
    // Stable, so windows that report the same z-order keep the order they came in.
    ordered.sort_by_key(|w| w.z_order);
    let mut names: Vec<String> = Vec::new();
    for window in ordered {
        if window.visible && !window.title.is_empty() && !names.contains(&window.title) {
            names.push(window.title.clone());
        }
    }
    names
}

/// The observation's window title: the foreground window's, or [`DESKTOP_TITLE`] when the
/// desktop or an untitled window is in front, or nothing is.
pub fn foreground_title(foreground: Option<&str>) -> String {
    match foreground {
        Some(title) if !title.is_empty() && title != PROGRAM_MANAGER => title.to_owned(),
        _ => DESKTOP_TITLE.to_owned(),
    }
}

/// [`foreground_title`] of the window marked focused in `windows`.
pub fn foreground_title_of(windows: &[WindowInfo]) -> String {
    foreground_title(windows.iter().find(|w| w.focused).map(|w| w.title.as_str()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Rect;

    fn window(id: u64, title: &str, z_order: u32) -> WindowInfo {
        WindowInfo {
            id,
            title: title.to_owned(),
            class_name: "C".to_owned(),
            process_id: 1,
            process_name: "p.exe".to_owned(),
            rect: Rect::new(0, 0, 10, 10),
            visible: true,
            minimized: false,
            maximized: false,
            focused: false,
            z_order,
        }
    }

    #[test]
    fn minimised_windows_are_listed_and_titles_appear_once_topmost_first() {
        let mut minimised = window(3, "Untitled - Notepad", 2);
        minimised.minimized = true;
        let mut hidden = window(4, "Hidden", 1);
        hidden.visible = false;
        let windows = vec![
            window(5, PROGRAM_MANAGER, 4),
            window(1, "Report.docx - Word", 3),
            window(2, "Report.docx - Word", 0),
            minimised,
            hidden,
            window(6, "", 5),
        ];
        assert_eq!(window_names(&windows), ["Report.docx - Word", "Untitled - Notepad", PROGRAM_MANAGER]);
    }

    #[test]
    fn the_desktop_and_untitled_windows_are_called_desktop() {
        assert_eq!(foreground_title(Some(PROGRAM_MANAGER)), "Desktop");
        assert_eq!(foreground_title(Some("")), "Desktop");
        assert_eq!(foreground_title(None), "Desktop");
        assert_eq!(foreground_title(Some("Untitled - Notepad")), "Untitled - Notepad");
        let mut front = window(1, PROGRAM_MANAGER, 0);
        front.focused = true;
        assert_eq!(foreground_title_of(&[front, window(2, "Other", 1)]), "Desktop");
    }
}
