//! The browser inside the guest over the DevTools protocol, through the
//! guest's websocket relay (`/v1/browser/devtools/...`).
//!
//! - [`cdp`]: [`cdp::CdpSession`], commands by id over one target's websocket, and the target list.
//! - [`dom`]: [`dom::dom_elements`], the front page's elements in screen pixels (upstream Navi's `webparse`).
//! - [`page`]: a page's title, address and HTML (upstream's `page_info` and `active_tab_info`).
//!
//! It is not the tab setup steps (`crate::setup::cdp`, plain DevTools HTTP).

pub mod cdp;
pub mod dom;
pub mod page;

#[cfg(test)]
pub(crate) mod fake;
#[cfg(test)]
mod tests;

pub use cdp::{CdpError, CdpSession};
pub use dom::{dom_elements, DomElement};
pub use page::PageInfo;
