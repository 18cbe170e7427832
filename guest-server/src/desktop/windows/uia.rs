//! The `uia` accessibility source: IUIAutomation with one cache request per window.
//!
//! The walks run in a worker process of their own (`arena-guest uia-worker`,
//! [`crate::desktop::uia_process`]): COM's multithreaded apartment and UI Automation's
//! client state are per process, so only a new process starts UI Automation afresh. Each
//! top-level window costs one cross-process call (`BuildUpdatedCache` with
//! `TreeScope_Subtree` and every property the output needs); the walk then reads the
//! cache. `IUIAutomation2`'s transaction timeout bounds that call by the window's share
//! of the time budget. The tree is UIA's raw view by default (every element, as
//! pywinauto's `backend="uia"`, which produced upstream's trees and marks, walks it);
//! `--uia-view control` walks the control view instead ([`UiaView`]): both the cache
//! requests' filter and the fallback's walker follow the choice.
//!
//! That call is all or nothing: a heavy window (a browser page, LibreOffice, VS Code)
//! that does not finish within its share adds nothing. It runs on a thread of its own
//! ([`call_detached`]), so one a provider keeps past its timeout is abandoned there and
//! never holds up what follows. So when it fails, the window is
//! read element by element instead ([`TreeSource::prepare_partial`]): each element and
//! then each child is fetched with a cache request for that element alone, through the
//! chosen view's walker, and the walk keeps whatever it reads before the window's deadline.
//!
//! Each window's opening (`ElementFromHandleBuildCache`, which also caches the
//! window's own properties) runs with connection and transaction timeouts set just
//! before it; a window that fails to open is listed in `windows_walked` with the reason.
//!
//! If a request does not come back in time (a provider that hangs beyond the
//! transaction timeout), the worker process is ended and the next request starts a new
//! one. [`UiaWorker::recreate`] ends it too (the health stage's revival).
//!
//! Where UI Automation is missing (Wine), creating `CUIAutomation` fails: the worker
//! says so once, and every later request is answered at once with
//! [`DesktopError::Unsupported`].

use std::sync::Mutex;
use std::time::{Duration, Instant};

use arena_shared::observation::{A11yBackend, A11yNode, A11yTree, TreeBudget};
use windows::core::{AgileReference, Interface};
use windows::Win32::Foundation::HWND;
use windows::Win32::System::Com::{CoCreateInstance, CLSCTX_INPROC_SERVER, COINIT_MULTITHREADED};
use windows::Win32::System::Variant::{VariantClear, VARIANT, VT_BOOL, VT_BSTR, VT_I4};
use windows::Win32::UI::Accessibility::*;

use super::sys::{ComApartment, Hwnd};
use super::window;
use crate::config::UiaView;
use crate::desktop::uia_health::{call_detached, ThreadCap};
use crate::desktop::uia_process::{self, WorkerAnswer, WorkerProcess, WorkerRequest, SUBCOMMAND};
use crate::desktop::{DesktopError, DesktopResult};
use arena_a11y_walk::{self as a11y_walk, TreeSource, UiaProps};

/// Extra time the caller waits beyond the walk's own budget before abandoning the worker.
const REPLY_GRACE: Duration = Duration::from_secs(3);

/// Properties the cache request fetches: everything [`UiaProps`] needs.
const PROPERTIES: [UIA_PROPERTY_ID; 18] = [
    UIA_NamePropertyId,
    UIA_ClassNamePropertyId,
    UIA_ControlTypePropertyId,
    UIA_BoundingRectanglePropertyId,
    UIA_IsEnabledPropertyId,
    UIA_IsOffscreenPropertyId,
    UIA_HasKeyboardFocusPropertyId,
    UIA_IsValuePatternAvailablePropertyId,
    UIA_ValueValuePropertyId,
    UIA_ValueIsReadOnlyPropertyId,
    UIA_IsWindowPatternAvailablePropertyId,
    UIA_WindowWindowVisualStatePropertyId,
    UIA_IsExpandCollapsePatternAvailablePropertyId,
    UIA_ExpandCollapseExpandCollapseStatePropertyId,
    UIA_IsSelectionItemPatternAvailablePropertyId,
    UIA_SelectionItemIsSelectedPropertyId,
    UIA_IsTogglePatternAvailablePropertyId,
    UIA_ToggleToggleStatePropertyId,
];

/// How long a new worker process may take to start, on top of a request's own time.
const START_GRACE: Duration = Duration::from_secs(10);

#[derive(Debug)]
struct State {
    /// The worker process (started on first use), which walks the view chosen.
    process: WorkerProcess,
    /// Why UI Automation cannot be used here, once a worker found out.
    unavailable: Option<String>,
}

/// The handle the backend keeps: the UI Automation worker process
/// (`arena-guest uia-worker`, [`crate::desktop::uia_process`]), started on first use.
#[derive(Debug)]
pub(super) struct UiaWorker {
    state: Mutex<State>,
}

impl UiaWorker {
    /// A worker (started on first use) that walks `view`: this same exe, run
    /// as `uia-worker`, in the server's session, without a console window.
    pub(super) fn new(view: UiaView) -> UiaWorker {
        let process = WorkerProcess::new(move || {
            use std::os::windows::process::CommandExt;
            let exe = std::env::current_exe().unwrap_or_else(|_| "arena-guest.exe".into());
            let mut command = std::process::Command::new(exe);
            command.args([SUBCOMMAND, "--view", view_name(view)]);
            // CREATE_NO_WINDOW: a console program started without a console of its own.
            command.creation_flags(0x0800_0000);
            command
        });
        UiaWorker { state: Mutex::new(State { process, unavailable: None }) }
    }

    /// Walks the visible top-level windows with UI Automation, in the worker process.
    ///
    /// # Errors
    ///
    /// [`DesktopError::Unsupported`] where UI Automation does not exist,
    /// [`DesktopError::Timeout`] when the worker does not answer in time (it is
    /// then ended, and the next request starts a new one), and
    /// [`DesktopError::Os`] when it cannot be started.
    pub(super) fn tree(&self, budget: &TreeBudget, foreground_only: bool) -> DesktopResult<A11yTree> {
        let mut state = self.lock();
        if let Some(why) = &state.unavailable {
            return Err(DesktopError::Unsupported(why.clone()));
        }
        let wait = Duration::from_millis(budget.max_ms) + REPLY_GRACE + START_GRACE;
        let result = state.process.request(WorkerRequest { budget: *budget, foreground_only }, wait);
        if let Err(DesktopError::Unsupported(why)) = &result {
            state.unavailable = Some(why.clone());
            state.process.restart();
        }
        result
    }

    /// Revives UI Automation: ends the worker process, so the next request
    /// starts a new one, with a new COM apartment and a new UI Automation client
    /// state (a new thread in this process would share both).
    pub(super) fn recreate(&self) {
        tracing::info!("restarting the UI Automation worker process");
        self.lock().process.restart();
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// The `--view` word of the worker's command line.
fn view_name(view: UiaView) -> &'static str {
    match view {
        UiaView::Raw => "raw",
        UiaView::Control => "control",
    }
}

/// The worker process's side (`arena-guest uia-worker --view VIEW`): answers the
/// guest's walk requests on standard input and output until the input closes.
///
/// # Errors
///
/// Writing an answer failed (the guest went away).
pub(super) fn run_worker_process(view: UiaView) -> std::io::Result<()> {
    let stdin = std::io::stdin();
    let stdout = std::io::stdout();
    let setup = ComApartment::init(COINIT_MULTITHREADED).and_then(|com| setup(view).map(|uia| (com, uia)));
    let (_com, uia) = match setup {
        Ok(ok) => ok,
        Err(err) => {
            let why = match err {
                DesktopError::Unsupported(m) => m,
                other => format!("UI Automation could not start: {other}; use backend=win32"),
            };
            return uia_process::serve(stdin.lock(), stdout.lock(), |_| WorkerAnswer::Unsupported(why.clone()));
        }
    };
    let fetches = ThreadCap::new(MAX_FETCH_THREADS);
    uia_process::serve(stdin.lock(), stdout.lock(), |request| {
        let mut source = UiaSource {
            uia: &uia,
            fetches: &fetches,
            live: false,
            budget_ms: request.budget.max_ms,
            failures: Vec::new(),
        };
        WorkerAnswer::from_result(a11y_walk::walk(
            &mut source,
            A11yBackend::Uia,
            &request.budget,
            request.foreground_only,
        ))
    })
}

/// The COM objects of the worker thread.
struct Uia {
    automation: IUIAutomation,
    cache: IUIAutomationCacheRequest,
    /// The same properties for one element alone: the element-by-element fallback.
    element_cache: IUIAutomationCacheRequest,
    /// The walker of the chosen view, which the fallback moves through children with.
    walker: IUIAutomationTreeWalker,
    /// For the per-window transaction timeout (Windows 8 and later).
    automation2: Option<IUIAutomation2>,
}

fn unsupported(what: &str, err: &windows::core::Error) -> DesktopError {
    DesktopError::Unsupported(format!(
        "UI Automation is not available on this system ({what} failed: {}); use backend=win32",
        super::sys::describe(err)
    ))
}

fn setup(view: UiaView) -> DesktopResult<Uia> {
    // SAFETY: creating the in-process UIA client object on a COM-initialised thread.
    let automation: IUIAutomation = unsafe { CoCreateInstance(&CUIAutomation8, None, CLSCTX_INPROC_SERVER) }
        // SAFETY: as above; CUIAutomation is the pre-Windows-8 class.
        .or_else(|_| unsafe { CoCreateInstance(&CUIAutomation, None, CLSCTX_INPROC_SERVER) })
        .map_err(|err| unsupported("CoCreateInstance(CUIAutomation)", &err))?;
    // SAFETY: COM calls on live interfaces owned by this thread.
    let request = |scope: TreeScope| -> DesktopResult<IUIAutomationCacheRequest> {
        // SAFETY: COM calls on live interfaces owned by this thread.
        unsafe {
            let cache = automation.CreateCacheRequest().map_err(|err| unsupported("CreateCacheRequest", &err))?;
            for property in PROPERTIES {
                cache.AddProperty(property).map_err(|err| unsupported("AddProperty", &err))?;
            }
            cache.SetTreeScope(scope).map_err(|err| unsupported("SetTreeScope", &err))?;
            let filter = match view {
                UiaView::Raw => automation.RawViewCondition().map_err(|err| unsupported("RawViewCondition", &err))?,
                UiaView::Control => {
                    automation.ControlViewCondition().map_err(|err| unsupported("ControlViewCondition", &err))?
                }
            };
            cache.SetTreeFilter(&filter).map_err(|err| unsupported("SetTreeFilter", &err))?;
            Ok(cache)
        }
    };
    let cache = request(TreeScope_Subtree)?;
    let element_cache = request(TreeScope_Element)?;
    let walker = match view {
        // SAFETY: a COM call on the live automation object.
        UiaView::Raw => unsafe { automation.RawViewWalker() }.map_err(|err| unsupported("RawViewWalker", &err))?,
        // SAFETY: a COM call on the live automation object.
        UiaView::Control => {
            unsafe { automation.ControlViewWalker() }.map_err(|err| unsupported("ControlViewWalker", &err))?
        }
    };
    let automation2 = automation.cast::<IUIAutomation2>().ok();
    Ok(Uia { automation, cache, element_cache, walker, automation2 })
}

/// A VARIANT read from the cache, cleared on drop.
struct Variant(VARIANT);

impl Drop for Variant {
    fn drop(&mut self) {
        // SAFETY: the VARIANT came from UIA and is cleared exactly once.
        let _ = unsafe { VariantClear(&mut self.0) };
    }
}

impl Variant {
    fn vt(&self) -> u16 {
        // SAFETY: reading the tag of an initialised VARIANT.
        unsafe { self.0.Anonymous.Anonymous.vt.0 }
    }

    fn as_bool(&self) -> Option<bool> {
        // SAFETY: the tag says the union holds a VARIANT_BOOL.
        (self.vt() == VT_BOOL.0).then(|| unsafe { self.0.Anonymous.Anonymous.Anonymous.boolVal.as_bool() })
    }

    fn as_i32(&self) -> Option<i32> {
        // SAFETY: the tag says the union holds an i32.
        (self.vt() == VT_I4.0).then(|| unsafe { self.0.Anonymous.Anonymous.Anonymous.lVal })
    }

    fn as_string(&self) -> Option<String> {
        // SAFETY: the tag says the union holds a BSTR, owned by this VARIANT.
        (self.vt() == VT_BSTR.0).then(|| unsafe { self.0.Anonymous.Anonymous.Anonymous.bstrVal.to_string() })
    }
}

fn cached(elem: &IUIAutomationElement, property: UIA_PROPERTY_ID) -> Option<Variant> {
    // SAFETY: a cached read on a live element; the VARIANT goes to a guard.
    unsafe { elem.GetCachedPropertyValue(property) }.ok().map(Variant)
}

fn cached_bool(elem: &IUIAutomationElement, property: UIA_PROPERTY_ID) -> Option<bool> {
    cached(elem, property).and_then(|v| v.as_bool())
}

/// A pattern property, only when the element supports the pattern.
fn pattern<T>(elem: &IUIAutomationElement, available: UIA_PROPERTY_ID, read: impl FnOnce() -> Option<T>) -> Option<T> {
    if cached_bool(elem, available) == Some(true) {
        read()
    } else {
        None
    }
}

/// How long past the transaction timeout the caller waits for a bulk fetch
/// before abandoning it (a timeout that works returns first, with its own error).
const FETCH_GRACE: Duration = Duration::from_millis(500);

/// Most bulk fetches abandoned while their providers keep them, at once.
const MAX_FETCH_THREADS: usize = 4;

struct UiaSource<'a> {
    uia: &'a Uia,
    /// The threads of bulk fetches, abandoned ones included.
    fetches: &'a ThreadCap,
    /// The window being walked is read element by element (its subtree fetch failed).
    live: bool,
    /// The request's time budget, which bounds opening the windows.
    budget_ms: u64,
    /// Windows seen but not opened, with the reason (for `windows_walked`).
    failures: Vec<(u64, String)>,
}

/// Longest one cross-process call of the element-by-element fallback may take.
const LIVE_CALL_MS: u32 = 1_000;

impl TreeSource for UiaSource<'_> {
    type Elem = IUIAutomationElement;
    type Error = DesktopError;

    fn roots(&mut self, foreground_only: bool) -> DesktopResult<Vec<(u64, IUIAutomationElement)>> {
        let hwnds: Vec<HWND> = if foreground_only { vec![window::foreground()] } else { window::top_level() };
        let call_ms = root_call_ms(self.budget_ms);
        // Opening the windows may take at most a quarter of the budget; the rest is the walk's.
        let open_until = Instant::now() + Duration::from_millis(self.budget_ms / 4);
        let mut out = Vec::new();
        for hwnd in hwnds {
            // Hidden and cloaked windows, and tool windows nobody sees, are not walked
            // (`shell::seen_on_desktop`).
            if !window::seen(hwnd) {
                continue;
            }
            if Instant::now() >= open_until {
                self.failures.push((Hwnd::id(hwnd), "not opened: the time for opening windows ran out".into()));
                continue;
            }
            // Timeouts are set before every call, never inherited from whatever the last
            // window or request left (a partial read sets them as low as 100 ms).
            self.set_timeouts(call_ms, call_ms);
            // SAFETY: a COM call on the worker's live automation object; the root's own
            // properties come back cached, so a window whose subtree fetch fails later
            // is still listed with its own node without another cross-process call.
            match unsafe { self.uia.automation.ElementFromHandleBuildCache(hwnd, &self.uia.element_cache) } {
                Ok(elem) => out.push((Hwnd::id(hwnd), elem)),
                Err(err) => {
                    tracing::debug!(%err, "no UIA element for a window");
                    self.failures.push((
                        Hwnd::id(hwnd),
                        format!("ElementFromHandle failed within {call_ms} ms: {}", super::sys::describe(&err)),
                    ));
                }
            }
        }
        Ok(out)
    }

    fn root_failures(&mut self) -> Vec<(u64, String)> {
        std::mem::take(&mut self.failures)
    }

    fn foreground_id(&mut self) -> Option<u64> {
        let hwnd = window::foreground();
        (!hwnd.is_invalid()).then(|| Hwnd::id(hwnd))
    }

    fn prepare_partial(
        &mut self,
        root: &IUIAutomationElement,
        time: Duration,
        _failed: DesktopError,
    ) -> DesktopResult<IUIAutomationElement> {
        self.live = true;
        let ms = u32::try_from(time.as_millis()).unwrap_or(u32::MAX).clamp(100, LIVE_CALL_MS);
        self.set_timeouts(ms, ms);
        // The root's own properties were cached when it was opened (`roots`): nothing to
        // fetch, so an abandoned subtree fetch the provider is still busy with costs the
        // root nothing, and its children are read one by one, each call bounded.
        Ok(root.clone())
    }

    fn prepare(&mut self, root: &IUIAutomationElement, time: Duration) -> DesktopResult<IUIAutomationElement> {
        self.live = false;
        let ms = u32::try_from(time.as_millis()).unwrap_or(u32::MAX).max(100);
        self.set_timeouts(ms.min(2_000), ms);
        // The fetch runs on a thread of its own: a provider that keeps it past the
        // transaction timeout is abandoned there, and the element-by-element read
        // (prepare_partial) starts at once instead of queueing behind it here.
        // The objects cross threads as agile references (COM's own way to hand an
        // interface to another apartment's thread).
        let agile = |err: windows::core::Error| super::sys::os("RoGetAgileReference", &err);
        let root = AgileReference::new(root).map_err(agile)?;
        let cache = AgileReference::new(&self.uia.cache).map_err(agile)?;
        let fetched = call_detached(self.fetches, time + FETCH_GRACE, "BuildUpdatedCache", move || {
            let _com = ComApartment::init(COINIT_MULTITHREADED)?;
            let (root, cache) = (root.resolve().map_err(agile)?, cache.resolve().map_err(agile)?);
            // SAFETY: one cross-process call that fetches the window's whole cached subtree.
            let element =
                unsafe { root.BuildUpdatedCache(&cache) }.map_err(|err| super::sys::os("BuildUpdatedCache", &err))?;
            AgileReference::new(&element).map_err(agile)
        })??;
        fetched.resolve().map_err(agile)
    }

    fn record(&mut self, elem: &IUIAutomationElement) -> A11yNode {
        // SAFETY: cached reads on a live element; none of them crosses processes.
        let (name, class_name, control_type, rect, enabled, offscreen, focus) = unsafe {
            (
                elem.CachedName().map(|b| b.to_string()).unwrap_or_default(),
                elem.CachedClassName().map(|b| b.to_string()).unwrap_or_default(),
                elem.CachedControlType().map(|t| t.0).unwrap_or(0),
                elem.CachedBoundingRectangle().ok(),
                elem.CachedIsEnabled().map(|b| b.as_bool()).unwrap_or(false),
                elem.CachedIsOffscreen().map(|b| b.as_bool()).unwrap_or(false),
                elem.CachedHasKeyboardFocus().map(|b| b.as_bool()).unwrap_or(false),
            )
        };
        let bounds = rect.map_or([0.0; 4], |r| {
            [f64::from(r.left), f64::from(r.top), f64::from(r.right - r.left), f64::from(r.bottom - r.top)]
        });
        UiaProps {
            control_type,
            class_name,
            name,
            bounds,
            enabled,
            offscreen,
            has_keyboard_focus: focus,
            value: pattern(elem, UIA_IsValuePatternAvailablePropertyId, || {
                cached(elem, UIA_ValueValuePropertyId).and_then(|v| v.as_string())
            }),
            value_read_only: pattern(elem, UIA_IsValuePatternAvailablePropertyId, || {
                cached_bool(elem, UIA_ValueIsReadOnlyPropertyId)
            }),
            window_visual_state: pattern(elem, UIA_IsWindowPatternAvailablePropertyId, || {
                cached(elem, UIA_WindowWindowVisualStatePropertyId).and_then(|v| v.as_i32())
            }),
            expand_collapse_state: pattern(elem, UIA_IsExpandCollapsePatternAvailablePropertyId, || {
                cached(elem, UIA_ExpandCollapseExpandCollapseStatePropertyId).and_then(|v| v.as_i32())
            }),
            selected: pattern(elem, UIA_IsSelectionItemPatternAvailablePropertyId, || {
                cached_bool(elem, UIA_SelectionItemIsSelectedPropertyId)
            }),
            toggle_state: pattern(elem, UIA_IsTogglePatternAvailablePropertyId, || {
                cached(elem, UIA_ToggleToggleStatePropertyId).and_then(|v| v.as_i32())
            }),
        }
        .into_node()
    }

    fn children(&mut self, elem: &IUIAutomationElement, limit: usize) -> Vec<IUIAutomationElement> {
        if self.live {
            return self.live_children(elem, limit);
        }
        // SAFETY: reads the cached children array of a live element.
        let Ok(array) = (unsafe { elem.GetCachedChildren() }) else {
            return Vec::new();
        };
        // SAFETY: as above.
        let len = unsafe { array.Length() }.unwrap_or(0).max(0) as usize;
        (0..len.min(limit.saturating_add(1)))
            // SAFETY: index < Length.
            .filter_map(|i| unsafe { array.GetElement(i as i32) }.ok())
            .collect()
    }
}

/// The connection and transaction timeout of opening one window (`ElementFromHandle`):
/// an eighth of the request's budget, between 100 ms and 1 s.
fn root_call_ms(budget_ms: u64) -> u32 {
    u32::try_from((budget_ms / 8).clamp(100, 1_000)).unwrap_or(1_000)
}

impl UiaSource<'_> {
    /// Sets `IUIAutomation2`'s connection and transaction timeouts (Windows 8 and later;
    /// without it, UIA's defaults apply).
    fn set_timeouts(&self, connection_ms: u32, transaction_ms: u32) {
        if let Some(a2) = &self.uia.automation2 {
            // SAFETY: COM calls on the worker's live automation object.
            unsafe {
                let _ = a2.SetConnectionTimeout(connection_ms);
                let _ = a2.SetTransactionTimeout(transaction_ms);
            }
        }
    }

    /// Up to `limit + 1` children of `elem` through the chosen view's walker, each fetched
    /// with its own properties cached (the fallback of a window whose subtree fetch failed).
    fn live_children(&self, elem: &IUIAutomationElement, limit: usize) -> Vec<IUIAutomationElement> {
        let mut out = Vec::new();
        // SAFETY: cross-process calls on live elements, each bounded by the transaction timeout.
        let mut next = unsafe { self.uia.walker.GetFirstChildElementBuildCache(elem, &self.uia.element_cache) };
        while let Ok(child) = next {
            if out.len() > limit {
                break;
            }
            // SAFETY: as above.
            next = unsafe { self.uia.walker.GetNextSiblingElementBuildCache(&child, &self.uia.element_cache) };
            out.push(child);
        }
        out
    }
}
