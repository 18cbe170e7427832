// arena:dom-elements — evaluated in the front page by host-client/src/browser/dom.rs.
// Answers the page's interactive elements in CSS pixels of the viewport, and the
// window geometry the host needs to place them on the screen.
(() => {
  const INTERACTIVE = [
    "a[href]", "area[href]", "input:not([disabled])", "select:not([disabled])",
    "textarea:not([disabled])", "button:not([disabled])", "iframe", "[tabindex]",
    "[contenteditable=true]", "[role]", "[aria-label]", "[onclick]", "video", "svg",
  ].join(",");
  const KEEP_ATTRS = ["aria", "title", "alt", "label", "value", "src", "href", "data-", "placeholder", "role", "id", "class"];

  // Every match under `root`, shadow roots included.
  const collect = (root, out) => {
    for (const el of root.querySelectorAll(INTERACTIVE)) {
      if (el.getAttribute("tabindex") !== "-1") out.push(el);
    }
    for (const el of root.querySelectorAll("*")) {
      if (el.shadowRoot) collect(el.shadowRoot, out);
    }
    return out;
  };

  // The element a click at (x, y) lands on, looking into shadow roots.
  const hit = (x, y) => {
    let el = document.elementFromPoint(x, y);
    while (el && el.shadowRoot) {
      const inner = el.shadowRoot.elementFromPoint(x, y);
      if (!inner || inner === el) break;
      el = inner;
    }
    return el;
  };

  const shorten = (text, max) => (text.length > max ? text.slice(0, max - 2) + ".." : text);

  // A short HTML description of an element without text: its tag, a few attributes, its children.
  const describe = (el, depth) => {
    const tag = el.tagName.toLowerCase();
    let attrs = "";
    for (const attr of el.attributes) {
      if (!KEEP_ATTRS.some((k) => attr.name.startsWith(k))) continue;
      let value = attr.value;
      if (attr.name === "src" || attr.name === "href") value = value.split("/").pop().slice(-25);
      attrs += ` ${attr.name}="${shorten(value, 50).replace(/"/g, "&quot;")}"`;
    }
    const inner = depth > 0 ? [...el.children].slice(0, 8).map((c) => describe(c, depth - 1)).join("") : "";
    return `<${tag}${attrs}>${inner}</${tag}>`;
  };

  const seen = new Set();
  let found = collect(document, []).filter((el) => !seen.has(el) && seen.add(el));
  const visible = new Map();
  for (const el of found) {
    const rects = [...el.getClientRects()].filter((r) => {
      const at = hit(r.left + r.width / 2, r.top + r.height / 2);
      return at === el || (at !== null && el.contains(at));
    });
    if (rects.reduce((sum, r) => sum + r.width * r.height, 0) >= 1) visible.set(el, rects);
  }
  found = [...visible.keys()];
  // Only the innermost: an element holding another listed one is left out.
  const innermost = found.filter((el) => !found.some((other) => other !== el && el.contains(other)));

  const items = innermost.map((el) => {
    const rects = visible.get(el);
    let box = rects[0];
    let text = el.textContent.trim();
    const walker = document.createTreeWalker(el, NodeFilter.SHOW_TEXT, {
      acceptNode: (n) => (n.textContent.trim() ? NodeFilter.FILTER_ACCEPT : NodeFilter.FILTER_SKIP),
    });
    const first = walker.nextNode();
    if (first) {
      const range = document.createRange();
      range.selectNodeContents(first);
      const r = range.getBoundingClientRect();
      if (r.width > 0 && r.height > 0) box = r;
      text = first.textContent;
    }
    if (!text) text = describe(el, 2);
    return { left: box.left, top: box.top, right: box.right, bottom: box.bottom, text, kind: el.tagName.toUpperCase() };
  });

  return {
    window: {
      screenX: window.screenX, screenY: window.screenY,
      outerWidth: window.outerWidth, outerHeight: window.outerHeight,
      innerWidth: window.innerWidth, innerHeight: window.innerHeight,
      devicePixelRatio: window.devicePixelRatio,
    },
    title: document.title,
    items,
  };
})()
