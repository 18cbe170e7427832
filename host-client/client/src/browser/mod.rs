//! The browser inside the guest over the DevTools protocol, through the
//! guest's websocket relay (`/v1/browser/devtools/...`), and where it keeps its profile.
//!
//! - [`profile`]: [`profile::user_data_dir`], the one rule for Chrome's and Edge's user-data folder
//!   (their `UserDataDir` policy, else the default folder).
//! - [`cdp`]: [`cdp::CdpSession`], commands by id over one target's websocket, and the target list.
//! - [`dom`]: [`dom::dom_elements`], the front page's elements in screen pixels (upstream Navi's `webparse`).
//! - [`page`]: a page's title, address and HTML (upstream's `page_info` and `active_tab_info`).
//!
//! - `fake` (tests, feature `fake-devtools`): a DevTools endpoint served with axum.
//!
//! It is not the setup steps that open and close tabs (those use plain DevTools HTTP
//! through the guest; `arena-setup`), and it imports nothing above this crate.

pub mod cdp;
pub mod dom;
pub mod page;
pub mod profile;

#[cfg(any(test, feature = "fake-devtools"))]
pub mod fake;
#[cfg(test)]
mod tests;

pub use cdp::{CdpError, CdpSession};
pub use dom::{dom_elements, DomElement};
pub use page::PageInfo;
