/* surfgen pages' shared helpers (the gallery and the 3-D viewer): an element builder, number
 * formatting, the toast and the JSON API client. A classic script, so the pages also work when
 * opened from disk (file://); it defines window.SURFGEN_UI and nothing else.
 * User text only ever reaches the page through textContent.
 */
window.SURFGEN_UI = (function () {
  "use strict";

  const $ = (id) => document.getElementById(id);

  // h("a", {class: "x", text: "label", onclick: f, href: url}, child…): attributes that are
  // null, undefined or false are left out, true gives an empty attribute.
  function h(tag, attrs, ...children) {
    const el = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v === null || v === undefined || v === false) continue;
      if (k === "class") el.className = v;
      else if (k === "text") el.textContent = v;
      else if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
      else el.setAttribute(k, v === true ? "" : v);
    }
    for (const c of children) if (c !== null && c !== undefined) el.append(c);
    return el;
  }

  // A metric for display: whole numbers grouped, others to `digits` significant digits (4).
  function fmt(v, digits) {
    if (v === null || v === undefined) return "–";
    if (typeof v === "number") {
      if (Number.isInteger(v)) return v.toLocaleString("en");
      return Number(v.toPrecision(digits || 4)).toString();
    }
    if (Array.isArray(v)) return v.map((x) => fmt(x, 3)).join(", ");
    if (typeof v === "object") return JSON.stringify(v);
    return String(v);
  }

  // toast(text, bad) shows #toast for okMs (bad: badMs) milliseconds.
  function toaster(okMs, badMs) {
    let timer = null;
    return function toast(text, bad) {
      const t = $("toast");
      t.textContent = text;
      t.className = "toast" + (bad ? " bad" : "");
      t.hidden = false;
      clearTimeout(timer);
      timer = setTimeout(() => { t.hidden = true; }, bad ? badMs : okMs);
    };
  }

  // api(path[, body]) against the server's JSON API at `base`: GET without a body, POST with
  // one; a refusal throws its {"error": …} text (or the HTTP status).
  function apiAt(base) {
    return async function api(path, body) {
      const init = body === undefined ? {} : {
        method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
      };
      const res = await fetch(base + path, init);
      let data = null;
      try { data = await res.json(); } catch (e) { data = null; }
      if (!res.ok) throw new Error((data && data.error) || res.status + " " + res.statusText);
      return data;
    };
  }

  return { $, h, fmt, toaster, apiAt };
})();
