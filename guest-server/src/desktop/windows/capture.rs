//! Screen geometry (monitors, DPI) and GDI screen capture with the real cursor.
//!
//! Capture is `BitBlt` from the screen DC into a top-down 32-bit DIB section, so the
//! pixels are read straight out of memory with no second copy through `GetDIBits`.
//! DXGI Desktop Duplication would be faster on real hardware but does not exist under
//! Wine and fails in some VMs; GDI works everywhere the server runs.

use arena_shared::geometry::{CoordinateSpace, Point, Rect};
use arena_shared::observation::{MonitorInfo, ScreenInfo};
use windows::Win32::Foundation::{LPARAM, RECT};
use windows::Win32::Graphics::Gdi::{
    BitBlt, CreateCompatibleDC, CreateDIBSection, EnumDisplayMonitors, GetMonitorInfoW, BITMAPINFO, BITMAPINFOHEADER,
    BI_RGB, CAPTUREBLT, DIB_RGB_COLORS, HDC, HGDIOBJ, HMONITOR, MONITORINFO, MONITORINFOEXW, SRCCOPY,
};
use windows::Win32::UI::HiDpi::{GetDpiForMonitor, MDT_EFFECTIVE_DPI};
use windows::Win32::UI::WindowsAndMessaging::{
    DrawIconEx, GetCursorInfo, GetIconInfo, GetSystemMetrics, CURSORINFO, CURSOR_SHOWING, DI_NORMAL, ICONINFO,
    MONITORINFOF_PRIMARY, SM_CXSCREEN, SM_CYSCREEN,
};

use super::input;
use super::sys::{os, Bitmap, MemoryDc, SelectGuard, WindowDc};
use crate::desktop::{DesktopError, DesktopResult, Frame};

/// One monitor as Windows reports it.
fn monitors() -> Vec<MonitorInfo> {
    // SAFETY: a callback for EnumDisplayMonitors below, which passes the LPARAM it was given.
    unsafe extern "system" fn collect(monitor: HMONITOR, _: HDC, _: *mut RECT, lparam: LPARAM) -> windows::core::BOOL {
        // SAFETY: lparam is the &mut Vec passed by monitors() below, alive for the whole call.
        let list = unsafe { &mut *(lparam.0 as *mut Vec<MonitorInfo>) };
        let mut info = MONITORINFOEXW {
            monitorInfo: MONITORINFO { cbSize: std::mem::size_of::<MONITORINFOEXW>() as u32, ..Default::default() },
            ..Default::default()
        };
        // SAFETY: info is a MONITORINFOEXW whose cbSize says so, as GetMonitorInfoW requires.
        if !unsafe { GetMonitorInfoW(monitor, &mut info as *mut MONITORINFOEXW as *mut MONITORINFO) }.as_bool() {
            return true.into();
        }
        let (mut dx, mut dy) = (96u32, 96u32);
        // SAFETY: valid out-pointers; on failure (old systems, Wine) the 96 DPI default stays.
        let _ = unsafe { GetDpiForMonitor(monitor, MDT_EFFECTIVE_DPI, &mut dx, &mut dy) };
        let r = info.monitorInfo.rcMonitor;
        list.push(MonitorInfo {
            name: crate::desktop::windows::text::from_wide_until_nul(&info.szDevice),
            rect: Rect::from_ltrb(r.left, r.top, r.right, r.bottom),
            scale_factor: f64::from(dx.max(1)) / 96.0,
            primary: info.monitorInfo.dwFlags & MONITORINFOF_PRIMARY != 0,
        });
        true.into()
    }
    let mut list: Vec<MonitorInfo> = Vec::new();
    // SAFETY: the callback only pushes into `list`, which outlives the call.
    let _ =
        unsafe { EnumDisplayMonitors(None, None, Some(collect), LPARAM(&mut list as *mut Vec<MonitorInfo> as isize)) };
    list
}

/// The primary monitor's rectangle (it always starts at 0,0).
fn primary_rect() -> Rect {
    // SAFETY: GetSystemMetrics has no preconditions.
    unsafe { Rect::new(0, 0, GetSystemMetrics(SM_CXSCREEN), GetSystemMetrics(SM_CYSCREEN)) }
}

/// Screen size, scale and monitors, in physical pixels (the process is per-monitor DPI aware).
pub(super) fn screen() -> DesktopResult<ScreenInfo> {
    let primary = primary_rect();
    if primary.is_empty() {
        return Err(DesktopError::Os {
            op: "screen",
            message: "the primary screen has no size (no desktop attached?)".into(),
        });
    }
    let mut monitors = monitors();
    if monitors.is_empty() {
        monitors.push(MonitorInfo { name: r"\\.\DISPLAY1".into(), rect: primary, scale_factor: 1.0, primary: true });
    }
    let scale = monitors.iter().find(|m| m.primary).map_or(1.0, |m| m.scale_factor);
    let (w, h) = (primary.width.max(0) as u32, primary.height.max(0) as u32);
    Ok(ScreenInfo {
        physical_width: w,
        physical_height: h,
        logical_width: (f64::from(w) / scale).round() as u32,
        logical_height: (f64::from(h) / scale).round() as u32,
        scale_factor: scale,
        monitors,
        coordinate_space: CoordinateSpace::Physical,
    })
}

/// Draws the real cursor shape into `hdc` (whose origin is screen point `origin`).
/// Returns the cursor position when it was drawn.
fn draw_real_cursor(hdc: HDC, origin: Point) -> Option<Point> {
    let mut info = CURSORINFO { cbSize: std::mem::size_of::<CURSORINFO>() as u32, ..Default::default() };
    // SAFETY: info's cbSize is set as the API requires.
    unsafe { GetCursorInfo(&mut info) }.ok()?;
    if info.flags.0 & CURSOR_SHOWING.0 == 0 || info.hCursor.is_invalid() {
        return None;
    }
    let mut icon = ICONINFO::default();
    // SAFETY: a valid out-pointer; the bitmaps it returns are owned by the guards below.
    unsafe { GetIconInfo(info.hCursor.into(), &mut icon) }.ok()?;
    let _mask = (!icon.hbmMask.is_invalid()).then(|| Bitmap(icon.hbmMask));
    let _color = (!icon.hbmColor.is_invalid()).then(|| Bitmap(icon.hbmColor));
    let p = Point::new(info.ptScreenPos.x, info.ptScreenPos.y);
    let x = p.x - origin.x - icon.xHotspot as i32;
    let y = p.y - origin.y - icon.yHotspot as i32;
    // SAFETY: hdc is a live memory DC with a bitmap selected; the cursor handle is the system's.
    unsafe { DrawIconEx(hdc, x, y, info.hCursor.into(), 0, 0, 0, None, DI_NORMAL) }.ok()?;
    Some(p)
}

/// Captures the primary monitor; draws the cursor (its real shape when Windows gives
/// one, else the static arrow upstream pastes) when `draw_cursor`.
///
/// The blit is `SRCCOPY` alone, as Pillow's `ImageGrab.grab()` (what pyautogui's
/// screenshot calls) does by default; `layered` adds `CAPTUREBLT`, as Pillow's
/// `include_layered_windows=True`. `CAPTUREBLT` makes GDI read windows drawn on top
/// of the desktop through the screen DC's slower path and can make the cursor
/// flicker while it runs.
///
/// # Errors
///
/// [`DesktopError::Os`] when a GDI call fails (no desktop, out of memory).
pub(super) fn capture(draw_cursor: bool, layered: bool) -> DesktopResult<Frame> {
    let area = primary_rect();
    if area.is_empty() {
        return Err(DesktopError::Os {
            op: "capture",
            message: "the primary screen has no size (no desktop attached?)".into(),
        });
    }
    let (w, h) = (area.width, area.height);
    let rop = if layered { SRCCOPY | CAPTUREBLT } else { SRCCOPY };
    let started = std::time::Instant::now();
    let screen =
        WindowDc::get(None).ok_or_else(|| DesktopError::Os { op: "capture", message: "GetDC(NULL) failed".into() })?;
    // SAFETY: screen.hdc is live; the result is owned by the guard at once.
    let mem = MemoryDc(unsafe { CreateCompatibleDC(Some(screen.hdc)) });
    if mem.0.is_invalid() {
        return Err(DesktopError::Os { op: "capture", message: "CreateCompatibleDC failed".into() });
    }
    let info = BITMAPINFO {
        bmiHeader: BITMAPINFOHEADER {
            biSize: std::mem::size_of::<BITMAPINFOHEADER>() as u32,
            biWidth: w,
            // Negative height: a top-down DIB, rows in screen order.
            biHeight: -h,
            biPlanes: 1,
            biBitCount: 32,
            biCompression: BI_RGB.0,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut bits: *mut core::ffi::c_void = std::ptr::null_mut();
    // SAFETY: info describes a w x h 32-bit DIB; `bits` receives its memory, owned by the bitmap.
    let dib = Bitmap(
        unsafe { CreateDIBSection(Some(mem.0), &info, DIB_RGB_COLORS, &mut bits, None, 0) }
            .map_err(|err| os("CreateDIBSection", &err))?,
    );
    if bits.is_null() {
        return Err(DesktopError::Os { op: "capture", message: "CreateDIBSection returned no pixels".into() });
    }
    let cursor = {
        // SAFETY: mem and dib are live and outlive the guard (declared before it).
        let _selected = unsafe { SelectGuard::select(mem.0, HGDIOBJ(dib.0 .0)) };
        // SAFETY: both DCs are live; the rectangle lies within the DIB.
        unsafe { BitBlt(mem.0, 0, 0, w, h, Some(screen.hdc), area.x, area.y, rop) }
            .map_err(|err| os("BitBlt", &err))?;
        if draw_cursor {
            draw_real_cursor(mem.0, Point::new(area.x, area.y))
        } else {
            None
        }
    };
    let blit_ms = started.elapsed().as_millis() as u64;
    let len = (w as usize) * (h as usize) * 4;
    // SAFETY: the DIB section holds w*h 32-bit pixels at `bits` and lives until `dib` drops below.
    let pixels = unsafe { std::slice::from_raw_parts(bits as *const u8, len) };
    let mut rgba = Vec::with_capacity(len);
    for px in pixels.chunks_exact(4) {
        rgba.extend_from_slice(&[px[2], px[1], px[0], 255]);
    }
    drop(dib);
    tracing::debug!(
        blit_ms,
        convert_ms = started.elapsed().as_millis() as u64 - blit_ms,
        width = w,
        height = h,
        "captured the screen"
    );
    let mut image = image::RgbaImage::from_raw(w as u32, h as u32, rgba)
        .ok_or_else(|| DesktopError::Os { op: "capture", message: "pixel buffer size mismatch".into() })?;
    let position = input::cursor().ok();
    let cursor_drawn = match (draw_cursor, cursor) {
        (false, _) => false,
        (true, Some(_)) => true,
        (true, None) => match position {
            // No cursor shape to draw (hidden cursor, Wine without one): draw upstream's arrow.
            Some(p) => {
                crate::imaging::draw_cursor(&mut image, Point::new(p.x - area.x, p.y - area.y));
                true
            }
            None => false,
        },
    };
    Ok(Frame { image, cursor: cursor.or(position), cursor_drawn })
}
