//! The stub's mutable desktop state: windows in z-order, focus, text buffers, the
//! cursor, held buttons and keys, the clipboard and the registry.
//!
//! Everything here is plain data behind the one mutex of [`super::StubDesktop`];
//! no I/O happens in this module.

use std::path::PathBuf;

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::{Point, Rect};
use arena_shared::observation::{A11yNode, WindowInfo};

use super::registry::Registry;
use crate::desktop::windows::shell;
use crate::desktop::{ClipboardData, DesktopError, DesktopResult, WindowState};

/// Height of a window's title bar, inside its 1-pixel border.
pub(crate) const TITLE_H: i32 = 30;
/// Width of each caption button (minimise, maximise, close) at the right of the title bar.
pub(crate) const CAPTION_W: i32 = 46;
/// Height of the taskbar, which the maximised window rectangle leaves free.
pub(crate) const TASKBAR_H: i32 = 40;
/// Width of one glyph of the 8x8 font.
pub(crate) const GLYPH_W: i32 = 8;
/// Height of one text line in a window body.
pub(crate) const LINE_H: i32 = 12;
/// Padding between a body's edge and its text.
pub(crate) const BODY_PAD: i32 = 4;
/// Width of a File Explorer window's navigation pane.
pub(crate) const EXPLORER_NAV_W: i32 = 160;
/// Height of a row in File Explorer's panes.
pub(crate) const EXPLORER_ROW_H: i32 = 16;
/// The navigation pane's entries, as Windows 11's File Explorer lists them first.
pub(crate) const EXPLORER_NAV: [&str; 8] =
    ["Home", "Desktop", "Downloads", "Documents", "Pictures", "Music", "Videos", "This PC"];
/// Most entries a File Explorer window lists (a folder may hold any number).
pub(crate) const EXPLORER_MAX_ITEMS: usize = 500;

/// What the stub's windows show of the file system, read before the state is locked:
/// the Desktop folder's names (the desktop icons) and each File Explorer window's.
#[derive(Debug, Clone, Default)]
pub(crate) struct Listings {
    pub(crate) desktop: Vec<String>,
    pub(crate) folders: std::collections::HashMap<u64, Vec<String>>,
}
/// The first window id, as a real desktop's first HWNDs look.
pub(crate) const FIRST_WINDOW_ID: u64 = 0x10010;
/// The first fake process id.
pub(crate) const FIRST_PID: u32 = 1000;
/// Most actions the log keeps; older ones are dropped.
pub(crate) const LOG_CAPACITY: usize = 1000;
/// Longest typed text the log keeps whole, in characters; longer ones are cut there.
const LOG_TEXT_CHARS: usize = 4096;

/// A caption button of a title bar.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Caption {
    Minimize,
    Maximize,
    Close,
}

/// What a point of a window is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Hit {
    TitleBar,
    Button(Caption),
    Body,
    /// The window's taskbar button.
    Taskbar,
}

/// A window's document: its text, a caret (in characters) and whether everything is selected.
///
/// Selection is all-or-nothing: `ctrl+a` selects everything, and the next edit replaces it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) struct TextBuf {
    pub(crate) text: String,
    pub(crate) caret: usize,
    pub(crate) all_selected: bool,
}

impl TextBuf {
    pub(crate) fn new(text: String) -> TextBuf {
        let caret = text.chars().count();
        TextBuf { text, caret, all_selected: false }
    }

    fn byte_at(&self, chars: usize) -> usize {
        self.text.char_indices().nth(chars).map_or(self.text.len(), |(i, _)| i)
    }

    fn len(&self) -> usize {
        self.text.chars().count()
    }

    /// Replaces the selection, or inserts at the caret.
    pub(crate) fn insert(&mut self, s: &str) {
        if self.all_selected {
            self.text.clear();
            self.caret = 0;
            self.all_selected = false;
        }
        let at = self.byte_at(self.caret);
        self.text.insert_str(at, s);
        self.caret += s.chars().count();
    }

    pub(crate) fn backspace(&mut self) {
        if self.take_selection().is_some() || self.caret == 0 {
            return;
        }
        let (start, end) = (self.byte_at(self.caret - 1), self.byte_at(self.caret));
        self.text.replace_range(start..end, "");
        self.caret -= 1;
    }

    pub(crate) fn delete(&mut self) {
        if self.take_selection().is_some() || self.caret >= self.len() {
            return;
        }
        let (start, end) = (self.byte_at(self.caret), self.byte_at(self.caret + 1));
        self.text.replace_range(start..end, "");
    }

    pub(crate) fn select_all(&mut self) {
        self.all_selected = true;
        self.caret = self.len();
    }

    /// The selected text, if anything is selected.
    pub(crate) fn selection(&self) -> Option<&str> {
        (self.all_selected && !self.text.is_empty()).then_some(self.text.as_str())
    }

    /// Removes and returns the selection.
    pub(crate) fn take_selection(&mut self) -> Option<String> {
        if !self.all_selected {
            return None;
        }
        self.all_selected = false;
        self.caret = 0;
        Some(std::mem::take(&mut self.text))
    }

    /// Line index and column of the caret, counting `\n` as the line break.
    fn caret_line_col(&self) -> (usize, usize) {
        let before: String = self.text.chars().take(self.caret).collect();
        let line = before.matches('\n').count();
        let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count());
        (line, col)
    }

    /// Character index of `line`, `col` (clamped to the line's end).
    fn index_of(&self, line: usize, col: usize) -> usize {
        let mut index = 0;
        for (i, l) in self.text.split('\n').enumerate() {
            let len = l.chars().count();
            if i == line {
                return index + col.min(len);
            }
            index += len + 1;
        }
        self.len()
    }

    /// Moves the caret for a navigation key; `doc` is ctrl (document-wide home and end).
    pub(crate) fn navigate(&mut self, key: &str, doc: bool) {
        let was_selected = std::mem::replace(&mut self.all_selected, false);
        let (line, col) = self.caret_line_col();
        self.caret = match key {
            "left" if was_selected => 0,
            "left" => self.caret.saturating_sub(1),
            "right" if was_selected => self.len(),
            "right" => (self.caret + 1).min(self.len()),
            "home" if doc => 0,
            "home" => self.index_of(line, 0),
            "end" if doc => self.len(),
            "end" => self.index_of(line, usize::MAX),
            "up" if line == 0 => 0,
            "up" => self.index_of(line - 1, col),
            "down" if line + 1 >= self.text.split('\n').count() => self.len(),
            "down" => self.index_of(line + 1, col),
            "pageup" => 0,
            "pagedown" => self.len(),
            _ => self.caret,
        };
    }

    /// Places the caret at a visual row and column of the wrapped layout.
    pub(crate) fn place_caret(&mut self, lines: &[VisualLine], row: usize, col: usize) {
        self.all_selected = false;
        self.caret = match lines.get(row) {
            Some(line) => line.start + col.min(line.len),
            None => self.len(),
        };
    }
}

/// One row of wrapped text: where it starts in the buffer (in characters) and how many it shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct VisualLine {
    pub(crate) start: usize,
    pub(crate) len: usize,
}

/// Wraps `text` into rows of at most `cols` characters, breaking at `\n` and hard at the width.
pub(crate) fn layout(text: &str, cols: usize) -> Vec<VisualLine> {
    let cols = cols.max(1);
    let mut lines = Vec::new();
    let mut start = 0;
    for line in text.split('\n') {
        let len = line.chars().count();
        if len == 0 {
            lines.push(VisualLine { start, len: 0 });
        }
        let mut offset = 0;
        while offset < len {
            let take = cols.min(len - offset);
            lines.push(VisualLine { start: start + offset, len: take });
            offset += take;
        }
        start += len + 1;
    }
    lines
}

/// A shell dialog the stub models: drawn and walked as its controls, not as a document.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Dialog {
    /// The Run dialog (`win+r`); its command field is the window's `text`.
    Run,
    /// A message box holding this message and an OK button.
    Message(String),
}

/// A push button of a [`Dialog`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DialogButton {
    Ok,
    Cancel,
    Browse,
}

impl DialogButton {
    pub(crate) fn label(self) -> &'static str {
        match self {
            DialogButton::Ok => "OK",
            DialogButton::Cancel => "Cancel",
            DialogButton::Browse => "Browse...",
        }
    }
}

/// The Run dialog's prompt, in our words (Windows' own sentence is Microsoft's text).
pub(crate) const RUN_PROMPT: &str = "Type the name of a program, folder, document or Internet resource to open it.";
/// The label of the Run dialog's command field, as Windows labels it.
pub(crate) const RUN_FIELD_LABEL: &str = "Open:";
/// The Run dialog's size.
pub(crate) const RUN_SIZE: (i32, i32) = (420, 200);
/// A message box's size.
pub(crate) const MESSAGE_SIZE: (i32, i32) = (420, 160);
/// Height of a dialog's command field and of its buttons.
pub(crate) const CONTROL_H: i32 = 24;
/// Width of a dialog button.
pub(crate) const BUTTON_W: i32 = 84;
/// A dialog's margin inside its body.
const DIALOG_PAD: i32 = 14;

/// Where a dialog's controls are: its text, its command field (the Run dialog's) and its buttons.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct DialogParts {
    /// Where the text starts, and how many characters a line holds.
    pub(crate) text_at: Point,
    pub(crate) text_cols: usize,
    /// The field's label position and the field.
    pub(crate) field: Option<(Point, Rect)>,
    pub(crate) buttons: Vec<(DialogButton, Rect)>,
}

/// A top-level window.
#[derive(Debug, Clone)]
pub(crate) struct Window {
    pub(crate) id: u64,
    pub(crate) title: String,
    pub(crate) class_name: String,
    pub(crate) process_name: String,
    pub(crate) pid: u32,
    pub(crate) rect: Rect,
    /// Where a maximised window returns to.
    pub(crate) restore_rect: Rect,
    pub(crate) visible: bool,
    pub(crate) minimized: bool,
    pub(crate) maximized: bool,
    pub(crate) refuse_close: bool,
    /// Program Manager: the desktop itself.
    pub(crate) is_desktop: bool,
    pub(crate) text: Option<TextBuf>,
    /// First visible row of the wrapped text.
    pub(crate) scroll: usize,
    /// Local file `ctrl+s` writes the document to.
    pub(crate) file: Option<PathBuf>,
    /// The local folder a File Explorer window shows.
    pub(crate) folder: Option<PathBuf>,
    /// Accessibility subtrees from the scenario.
    pub(crate) elements: Vec<A11yNode>,
    /// What the shell and UI Automation make of it (the scenario's window fields).
    pub(crate) model: WindowModel,
    /// The shell dialog it is, if it is one.
    pub(crate) dialog: Option<Dialog>,
}

/// A window's shell styles and UI Automation costs, as a scenario sets them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct WindowModel {
    /// `WS_EX_TOOLWINDOW`.
    pub(crate) tool_window: bool,
    /// A popup menu or drop-down owned by another window: `WS_POPUP`, topmost, never focused.
    pub(crate) popup: bool,
    /// DWM cloaks it: never drawn, clicked or walked.
    pub(crate) cloaked: bool,
    /// How long UI Automation's whole-subtree fetch of it takes.
    pub(crate) bulk_fetch_ms: u64,
    /// The fetch ignores its timeout (a provider kept busy): it runs its whole time.
    pub(crate) bulk_fetch_hangs: bool,
    /// How long reading one of its elements by itself takes.
    pub(crate) element_ms: u64,
}

impl Window {
    /// Whether it is drawn and can be clicked.
    pub(crate) fn shown(&self) -> bool {
        self.visible && !self.minimized && !self.model.cloaked
    }

    /// What the shell would say about it, for [`crate::desktop::windows::shell::seen_on_desktop`];
    /// `foreground_pid` is the process of the focused window.
    pub(crate) fn facts(&self, foreground_pid: u32) -> shell::WindowFacts {
        let mut ex_style = 0;
        if self.model.tool_window || self.model.popup {
            ex_style |= shell::WS_EX_TOOLWINDOW;
        }
        if self.model.popup {
            ex_style |= shell::WS_EX_TOPMOST;
        }
        shell::WindowFacts {
            visible: self.visible,
            cloaked: u32::from(self.model.cloaked),
            ex_style,
            style: if self.model.popup { shell::WS_POPUP } else { 0 },
            foreground_process: self.pid == foreground_pid,
            shell_class: shell::shell_class(&self.class_name),
        }
    }

    pub(crate) fn title_bar(&self) -> Rect {
        let r = self.rect;
        Rect::new(r.x + 1, r.y + 1, (r.width - 2).max(0), TITLE_H.min((r.height - 2).max(0)))
    }

    pub(crate) fn body(&self) -> Rect {
        let r = self.rect;
        Rect::new(r.x + 1, r.y + 1 + TITLE_H, (r.width - 2).max(0), (r.height - 2 - TITLE_H).max(0))
    }

    /// A File Explorer window's navigation pane (left) and items view (right), in its body.
    pub(crate) fn explorer_panes(&self) -> (Rect, Rect) {
        let body = self.body();
        let nav_w = EXPLORER_NAV_W.min(body.width / 3);
        (
            Rect::new(body.x, body.y, nav_w, body.height),
            Rect::new(body.x + nav_w + 1, body.y, (body.width - nav_w - 1).max(0), body.height),
        )
    }

    /// Row `i` of a File Explorer pane: its navigation entries or its items.
    pub(crate) fn explorer_row(pane: Rect, i: usize) -> Rect {
        let y = pane.y + BODY_PAD + i32::try_from(i).unwrap_or(i32::MAX / 2).saturating_mul(EXPLORER_ROW_H);
        Rect::new(pane.x + BODY_PAD, y, (pane.width - 2 * BODY_PAD).max(0), EXPLORER_ROW_H - 2)
    }

    /// The caption buttons, right to left as they are laid out: close, maximise, minimise.
    pub(crate) fn captions(&self) -> [(Caption, Rect); 3] {
        let bar = self.title_bar();
        let at = |n: i32| Rect::new(bar.right() - CAPTION_W * n, bar.y, CAPTION_W, bar.height);
        [(Caption::Minimize, at(3)), (Caption::Maximize, at(2)), (Caption::Close, at(1))]
    }

    /// Text columns and rows the body shows.
    pub(crate) fn text_grid(&self) -> (usize, usize) {
        let body = self.body();
        let cols = ((body.width - 2 * BODY_PAD) / GLYPH_W).max(1) as usize;
        let rows = ((body.height - 2 * BODY_PAD) / LINE_H).max(0) as usize;
        (cols, rows)
    }

    /// The controls of a dialog window; `None` for other windows.
    pub(crate) fn dialog_parts(&self) -> Option<DialogParts> {
        let dialog = self.dialog.as_ref()?;
        let body = self.body();
        let text_at = Point::new(body.x + DIALOG_PAD, body.y + DIALOG_PAD);
        let text_cols = ((body.width - 2 * DIALOG_PAD) / GLYPH_W).max(1) as usize;
        let button_y = body.bottom() - DIALOG_PAD - CONTROL_H;
        let row = |labels: &[DialogButton]| -> Vec<(DialogButton, Rect)> {
            let n = labels.len() as i32;
            labels
                .iter()
                .enumerate()
                .map(|(i, b)| {
                    let x = body.right() - DIALOG_PAD - (n - i as i32) * (BUTTON_W + 8) + 8;
                    (*b, Rect::new(x, button_y, BUTTON_W, CONTROL_H))
                })
                .collect()
        };
        Some(match dialog {
            Dialog::Run => {
                let label_w = (RUN_FIELD_LABEL.len() as i32 + 1) * GLYPH_W;
                let field_y = button_y - DIALOG_PAD - CONTROL_H;
                let field = Rect::new(
                    text_at.x + label_w,
                    field_y,
                    (body.width - 2 * DIALOG_PAD - label_w).max(GLYPH_W),
                    CONTROL_H,
                );
                DialogParts {
                    text_at,
                    text_cols,
                    field: Some((Point::new(text_at.x, field_y + (CONTROL_H - 8) / 2), field)),
                    buttons: row(&[DialogButton::Ok, DialogButton::Cancel, DialogButton::Browse]),
                }
            }
            Dialog::Message(_) => DialogParts { text_at, text_cols, field: None, buttons: row(&[DialogButton::Ok]) },
        })
    }

    /// The dialog button at `p`, if any.
    pub(crate) fn dialog_button_at(&self, p: Point) -> Option<DialogButton> {
        self.dialog_parts()?.buttons.into_iter().find(|(_, r)| r.contains(p)).map(|(b, _)| b)
    }

    pub(crate) fn hit(&self, p: Point) -> Option<Hit> {
        if self.is_desktop || !self.rect.contains(p) {
            return self.rect.contains(p).then_some(Hit::Body);
        }
        if let Some((caption, _)) = self.captions().iter().find(|(_, r)| r.contains(p)) {
            return Some(Hit::Button(*caption));
        }
        if self.title_bar().contains(p) {
            return Some(Hit::TitleBar);
        }
        Some(Hit::Body)
    }

    pub(crate) fn info(&self, z: usize, focused: bool) -> WindowInfo {
        WindowInfo {
            id: self.id,
            title: self.title.clone(),
            class_name: self.class_name.clone(),
            process_id: self.pid,
            process_name: self.process_name.clone(),
            rect: self.rect,
            visible: self.visible,
            minimized: self.minimized,
            maximized: self.maximized,
            focused,
            z_order: u32::try_from(z).unwrap_or(u32::MAX),
        }
    }
}

/// What a new window looks like.
#[derive(Debug, Clone, Default)]
pub(crate) struct NewWindow {
    pub(crate) title: String,
    pub(crate) class_name: String,
    pub(crate) process_name: String,
    /// `None` gets a fresh pid.
    pub(crate) pid: Option<u32>,
    /// `None` gets a cascade position.
    pub(crate) rect: Option<Rect>,
    pub(crate) text: Option<String>,
    pub(crate) file: Option<PathBuf>,
    /// A File Explorer window: the local folder it lists.
    pub(crate) folder: Option<PathBuf>,
    pub(crate) elements: Vec<A11yNode>,
    pub(crate) refuse_close: bool,
    pub(crate) dialog: Option<Dialog>,
}

/// Held modifier keys, sided forms folded.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Modifiers {
    pub(crate) ctrl: bool,
    pub(crate) alt: bool,
    pub(crate) shift: bool,
    pub(crate) win: bool,
}

/// A title bar being dragged: the window and where in it the cursor grabbed it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Grab {
    pub(crate) window: u64,
    pub(crate) dx: i32,
    pub(crate) dy: i32,
}

/// A button press waiting for its release: where it went down and what it hit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Press {
    pub(crate) button: MouseButton,
    pub(crate) window: u64,
    pub(crate) hit: Hit,
}

/// The wallpaper scaled to the screen, with what it was made from.
#[derive(Debug, Clone)]
pub(crate) struct WallpaperCache {
    pub(crate) key: (PathBuf, u64, Option<std::time::SystemTime>, (u32, u32)),
    pub(crate) image: Option<image::RgbaImage>,
}

/// The whole mutable desktop.
#[derive(Debug)]
pub(crate) struct State {
    pub(crate) screen: (u32, u32),
    pub(crate) cursor: Point,
    /// Topmost first; Program Manager is always last.
    pub(crate) windows: Vec<Window>,
    /// The foreground window (Program Manager when the desktop has focus).
    pub(crate) focus: u64,
    pub(crate) next_id: u64,
    pub(crate) next_pid: u32,
    /// How many windows have been cascaded, for the next default position.
    pub(crate) cascade: i32,
    pub(crate) buttons: Vec<MouseButton>,
    pub(crate) press: Option<Press>,
    pub(crate) grab: Option<Grab>,
    pub(crate) mods: Modifiers,
    pub(crate) clipboard: ClipboardData,
    pub(crate) registry: Registry,
    /// The last [`LOG_CAPACITY`] actions (see [`State::record`]).
    pub(crate) log: std::collections::VecDeque<Action>,
    pub(crate) shutdown: bool,
    pub(crate) wallpaper: Option<WallpaperCache>,
    /// What the action being performed asks of the rest of the desktop (see `super::input::perform`).
    pub(crate) effects: Vec<Effect>,
    /// The command the Run dialog ran last, which it offers again (selected) when it opens.
    pub(crate) run_mru: Option<String>,
}

impl State {
    /// Logs `action`, keeping the log within [`LOG_CAPACITY`] actions and long typed
    /// texts within [`LOG_TEXT_CHARS`], so hours of typing cannot grow memory.
    pub(crate) fn record(&mut self, action: &Action) {
        let logged = match action {
            Action::TypeText { text, interval_ms } if text.chars().count() > LOG_TEXT_CHARS => {
                Action::TypeText { text: text.chars().take(LOG_TEXT_CHARS).collect(), interval_ms: *interval_ms }
            }
            other => other.clone(),
        };
        if self.log.len() >= LOG_CAPACITY {
            self.log.pop_front();
        }
        self.log.push_back(logged);
    }

    /// A desktop with only Program Manager.
    pub(crate) fn new(screen: (u32, u32)) -> State {
        let (w, h) = screen;
        let mut state = State {
            screen,
            cursor: Point::new((w / 2) as i32, (h / 2) as i32),
            windows: Vec::new(),
            focus: FIRST_WINDOW_ID,
            next_id: FIRST_WINDOW_ID,
            next_pid: FIRST_PID,
            cascade: 0,
            buttons: Vec::new(),
            press: None,
            grab: None,
            mods: Modifiers::default(),
            clipboard: ClipboardData::Empty,
            registry: Registry::seeded(),
            log: std::collections::VecDeque::new(),
            shutdown: false,
            wallpaper: None,
            effects: Vec::new(),
            run_mru: None,
        };
        let full = state.screen_rect();
        let pid = state.alloc_pid();
        let id = state.alloc_id();
        state.windows.push(Window {
            id,
            title: "Program Manager".into(),
            class_name: "Progman".into(),
            process_name: "explorer.exe".into(),
            pid,
            rect: full,
            restore_rect: full,
            visible: true,
            minimized: false,
            maximized: false,
            refuse_close: true,
            is_desktop: true,
            text: None,
            scroll: 0,
            file: None,
            folder: None,
            elements: Vec::new(),
            model: WindowModel::default(),
            dialog: None,
        });
        state.focus = id;
        state
    }

    fn alloc_id(&mut self) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        id
    }

    pub(crate) fn alloc_pid(&mut self) -> u32 {
        let pid = self.next_pid;
        self.next_pid += 1;
        pid
    }

    pub(crate) fn screen_rect(&self) -> Rect {
        Rect::new(0, 0, self.screen.0 as i32, self.screen.1 as i32)
    }

    /// The screen minus the taskbar: where maximised windows go.
    pub(crate) fn work_area(&self) -> Rect {
        let r = self.screen_rect();
        Rect::new(0, 0, r.width, (r.height - TASKBAR_H).max(1))
    }

    /// The process id of the shell (explorer.exe), which owns Program Manager, File
    /// Explorer windows and the shell's dialogs.
    pub(crate) fn shell_pid(&self) -> u32 {
        self.windows.iter().find(|w| w.is_desktop).map_or(FIRST_PID, |w| w.pid)
    }

    /// `win+r`: the Run dialog at the bottom left of the work area, focused, offering the
    /// last command it ran selected; Windows keeps one, so a second `win+r` brings it back.
    pub(crate) fn open_run_dialog(&mut self) {
        let mru = self.run_mru.clone().unwrap_or_default();
        if let Some(id) = self.windows.iter().find(|w| w.dialog == Some(Dialog::Run)).map(|w| w.id) {
            if let Some(window) = self.window_mut(id) {
                window.minimized = false;
                if let Some(buf) = window.text.as_mut() {
                    buf.select_all();
                }
            }
            // The id came from the window list just now.
            let _ = self.activate(id);
            return;
        }
        let work = self.work_area();
        let (w, h) = RUN_SIZE;
        let rect = Rect::new(work.x + 12, (work.bottom() - h - 12).max(0), w, h);
        let pid = self.shell_pid();
        let id = self.open(NewWindow {
            title: "Run".into(),
            class_name: "#32770".into(),
            process_name: "explorer.exe".into(),
            pid: Some(pid),
            rect: Some(rect),
            text: Some(mru),
            dialog: Some(Dialog::Run),
            ..NewWindow::default()
        });
        if let Some(buf) = self.window_mut(id).and_then(|w| w.text.as_mut()) {
            if !buf.text.is_empty() {
                buf.select_all();
            }
        }
    }

    /// A message box of the shell, centred on the work area and focused.
    pub(crate) fn open_message_box(&mut self, title: &str, message: &str) -> u64 {
        let work = self.work_area();
        let (w, h) = MESSAGE_SIZE;
        let rect = Rect::new(work.x + (work.width - w) / 2, work.y + (work.height - h) / 2, w, h);
        let pid = self.shell_pid();
        self.open(NewWindow {
            title: title.to_owned(),
            class_name: "#32770".into(),
            process_name: "explorer.exe".into(),
            pid: Some(pid),
            rect: Some(rect),
            dialog: Some(Dialog::Message(message.to_owned())),
            ..NewWindow::default()
        })
    }

    pub(crate) fn desktop_id(&self) -> u64 {
        self.windows.iter().find(|w| w.is_desktop).map_or(FIRST_WINDOW_ID, |w| w.id)
    }

    pub(crate) fn index(&self, id: u64) -> DesktopResult<usize> {
        self.windows
            .iter()
            .position(|w| w.id == id)
            .ok_or_else(|| DesktopError::NotFound(format!("no window with id {id:#x}")))
    }

    pub(crate) fn window(&self, id: u64) -> Option<&Window> {
        self.windows.iter().find(|w| w.id == id)
    }

    pub(crate) fn window_mut(&mut self, id: u64) -> Option<&mut Window> {
        self.windows.iter_mut().find(|w| w.id == id)
    }

    /// The focused window, unless the desktop has focus.
    pub(crate) fn focused_app_mut(&mut self) -> Option<&mut Window> {
        let focus = self.focus;
        self.windows.iter_mut().find(|w| w.id == focus && !w.is_desktop)
    }

    /// Opens a window on top, focused, and returns its id.
    pub(crate) fn open(&mut self, new: NewWindow) -> u64 {
        let id = self.alloc_id();
        let pid = new.pid.unwrap_or_else(|| self.alloc_pid());
        let rect = new.rect.unwrap_or_else(|| self.cascade_rect());
        self.windows.insert(
            0,
            Window {
                id,
                title: new.title,
                class_name: new.class_name,
                process_name: new.process_name,
                pid,
                rect,
                restore_rect: rect,
                visible: true,
                minimized: false,
                maximized: false,
                refuse_close: new.refuse_close,
                is_desktop: false,
                text: new.text.map(TextBuf::new),
                scroll: 0,
                file: new.file,
                folder: new.folder,
                elements: new.elements,
                model: WindowModel::default(),
                dialog: new.dialog,
            },
        );
        self.focus = id;
        id
    }

    /// The next default window position: a cascade from the top-left, 30 pixels a step,
    /// begun again when no window but the desktop is left (so an episode's windows
    /// open where they opened in the last one, whatever ran on the guest before).
    fn cascade_rect(&mut self) -> Rect {
        if self.windows.iter().all(|w| w.is_desktop) {
            self.cascade = 0;
        }
        let work = self.work_area();
        let step = self.cascade % 8;
        self.cascade += 1;
        let width = (work.width - 240).clamp(200, 960);
        let height = (work.height - 240).clamp(150, 640);
        Rect::new(60 + 30 * step, 40 + 30 * step, width, height)
    }

    /// Raises a window to the top (Program Manager stays at the bottom) and focuses it.
    pub(crate) fn activate(&mut self, id: u64) -> DesktopResult<()> {
        let index = self.index(id)?;
        if !self.windows[index].is_desktop {
            let window = self.windows.remove(index);
            self.windows.insert(0, window);
        }
        self.focus = id;
        Ok(())
    }

    /// Gives focus to the topmost shown window, or the desktop, after the focused one went away.
    pub(crate) fn refocus(&mut self) {
        self.focus = self
            .windows
            .iter()
            .find(|w| w.shown() && !w.is_desktop && !w.model.popup)
            .map_or_else(|| self.desktop_id(), |w| w.id);
    }

    /// The topmost shown window under `p`.
    pub(crate) fn window_at(&self, p: Point) -> Option<&Window> {
        self.windows.iter().find(|w| w.shown() && w.rect.contains(p))
    }

    pub(crate) fn set_state(&mut self, id: u64, state: WindowState) -> DesktopResult<()> {
        let index = self.index(id)?;
        let work = self.work_area();
        let window = &mut self.windows[index];
        if window.is_desktop {
            // Program Manager cannot be minimised or maximised; like ShowWindow on it, this does nothing.
            return Ok(());
        }
        match state {
            WindowState::Minimized => {
                window.minimized = true;
                if self.focus == id {
                    self.refocus();
                }
                return Ok(());
            }
            WindowState::Maximized => {
                if !window.maximized {
                    window.restore_rect = window.rect;
                }
                window.maximized = true;
                window.minimized = false;
                window.rect = work;
            }
            WindowState::Normal => {
                if window.minimized {
                    window.minimized = false;
                } else if window.maximized {
                    window.maximized = false;
                    window.rect = window.restore_rect;
                }
            }
        }
        self.activate(id)
    }

    /// `SetWindowPos` after a restore: the window takes `rect` (no longer minimised or
    /// maximised) and keeps its place in the z-order and the focus.
    pub(crate) fn move_window(&mut self, id: u64, rect: Rect) -> DesktopResult<()> {
        let index = self.index(id)?;
        let window = &mut self.windows[index];
        if window.is_desktop {
            return Err(DesktopError::PermissionDenied("Program Manager (the desktop) cannot be moved".into()));
        }
        window.minimized = false;
        window.maximized = false;
        window.rect = rect;
        window.restore_rect = rect;
        Ok(())
    }

    /// `WM_CLOSE`: the window goes away unless it refuses.
    pub(crate) fn close(&mut self, id: u64) -> DesktopResult<()> {
        let index = self.index(id)?;
        let window = &self.windows[index];
        if window.is_desktop {
            return Err(DesktopError::PermissionDenied("Program Manager (the desktop) cannot be closed".into()));
        }
        if window.refuse_close {
            tracing::debug!(id, title = %window.title, "stub window refuses to close");
            return Ok(());
        }
        self.windows.remove(index);
        if self.grab.is_some_and(|g| g.window == id) {
            self.grab = None;
        }
        if self.focus == id {
            self.refocus();
        }
        Ok(())
    }

    pub(crate) fn infos(&self) -> Vec<WindowInfo> {
        self.windows.iter().enumerate().map(|(z, w)| w.info(z, w.id == self.focus)).collect()
    }

    pub(crate) fn clamp(&self, p: Point) -> Point {
        Point::new(p.x.clamp(0, self.screen.0 as i32 - 1), p.y.clamp(0, self.screen.1 as i32 - 1))
    }
}

/// Something an action asks the desktop to do beyond the state (it needs the file system).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Effect {
    /// Open the `n`th Desktop item (sorted by name), after a double click on its icon.
    OpenDesktopItem(usize),
    /// Start a command line as the shell does (`win+e` starts `explorer`).
    Launch(String),
    /// The Run dialog `dialog` was told to run `line` (`enter` or its OK button).
    RunDialog { dialog: u64, line: String },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_editing_follows_the_caret() {
        let mut buf = TextBuf::new("héllo".into());
        buf.insert("!");
        assert_eq!(buf.text, "héllo!");
        buf.navigate("home", false);
        buf.insert(">");
        assert_eq!(buf.text, ">héllo!");
        buf.navigate("right", false);
        buf.delete();
        assert_eq!(buf.text, ">hllo!");
        buf.backspace();
        assert_eq!(buf.text, ">llo!");
        assert_eq!(buf.caret, 1);
        buf.select_all();
        assert_eq!(buf.selection(), Some(">llo!"));
        buf.insert("new");
        assert_eq!(buf.text, "new");
        buf.select_all();
        buf.backspace();
        assert_eq!(buf.text, "");
        assert_eq!(buf.selection(), None);
    }

    #[test]
    fn caret_moves_between_lines() {
        let mut buf = TextBuf::new("abc\nde\nfghij".into());
        buf.navigate("up", false);
        assert_eq!(buf.caret, 6, "end of \"de\"");
        buf.navigate("up", false);
        buf.insert("X");
        assert_eq!(buf.text, "abXc\nde\nfghij");
        buf.navigate("end", true);
        assert_eq!(buf.caret, buf.text.chars().count());
    }

    #[test]
    fn layout_wraps_and_breaks() {
        let lines = layout("abcdefg\n\nxy", 3);
        let got: Vec<(usize, usize)> = lines.iter().map(|l| (l.start, l.len)).collect();
        assert_eq!(got, vec![(0, 3), (3, 3), (6, 1), (8, 0), (9, 2)]);
    }
}
