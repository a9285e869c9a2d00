/* surfgen gallery: a grid of shapes to sort, filter, inspect and curate.
 *
 * The page carries its data (JSON in #gallery-data), so the same file works served by
 * `surfgen serve` (live: curation buttons call the JSON API, which writes the catalogue at once)
 * and exported by `surfgen gallery -o DIR` (read-only, opened from disk). User text is only ever
 * put in the page with textContent, never as HTML.
 */
(function () {
  "use strict";

  const DATA = JSON.parse(document.getElementById("gallery-data").textContent);
  const READONLY = !!DATA.readonly;
  const FRAMES = 12;
  const SPIN_MS = 110;
  const shapes = DATA.shapes;
  const byKey = new Map(shapes.map((s) => [s.key, s]));

  const SORTS = [
    ["index", "run, index"], ["genus", "genus"], ["components", "components"],
    ["faces", "faces"], ["area", "area"], ["volume", "volume"], ["stars", "stars"],
    ["box_fraction", "box fraction"], ["total_curvature", "total curvature"],
    ["largest_component_fraction", "largest component"], ["key", "key"], ["random", "random"],
  ];

  const state = {
    sort: "index", desc: false, tag: "", family: "", search: "", starred: false,
    showRejected: false, showDuplicates: false, whereKeys: null, visible: [], current: null, focus: null,
  };
  const $ = (id) => document.getElementById(id);

  const { h, fmt } = window.SURFGEN_UI;
  const short = (key) => key.slice(0, 8);
  // The 3-D page of a shape: served by `surfgen serve`, or written by `surfgen gallery --meshes`.
  const page3d = (s) => (!READONLY ? "shape/" + s.key : DATA.meshes && s.mesh ? "shapes/" + s.key + ".html" : null);
  const kfaces = (n) => (n >= 1000 ? (n / 1000).toFixed(n >= 10000 ? 0 : 1) + "k" : String(n));

  function value(s, field) {
    if (field === "index") return s.run * 1e9 + s.index;
    if (field === "key") return s.key;
    if (field in s && typeof s[field] !== "object") return s[field];
    const m = s.metrics || {};
    return field in m ? m[field] : null;
  }

  // ------------------------------------------------------------------ toast and API

  const toast = window.SURFGEN_UI.toaster(1800, 5000);
  const api = window.SURFGEN_UI.apiAt("api/");

  async function act(key, action, body) {
    if (READONLY) return;
    try {
      const data = await api("shapes/" + key + "/" + action, body || {});
      Object.assign(byKey.get(key), data.shape);
      refreshCard(key);
      if (state.current === key) fillDetail(key);
      renderTagOptions();
      const done = { star: "stars saved", reject: "rejected", unreject: "restored", tag: "tagged", untag: "tag removed", note: "note saved" };
      toast(done[action] || "saved");
    } catch (err) {
      toast(err.message, true);
    }
  }

  // ------------------------------------------------------------------ filtering and sorting

  function matches(s) {
    if (!state.showRejected && s.rejected) return false;
    if (!state.showDuplicates && s.duplicate_of) return false;
    if (state.starred && !(s.stars > 0)) return false;
    if (state.tag && !s.tags.includes(state.tag)) return false;
    if (state.family && s.family !== state.family) return false;
    if (state.whereKeys && !state.whereKeys.has(s.key)) return false;
    const q = state.search.trim().toLowerCase();
    if (q) {
      const hay = [s.key, s.formula, s.note || "", ...s.tags].join(" ").toLowerCase();
      if (!q.split(/\s+/).every((w) => hay.includes(w))) return false;
    }
    return true;
  }

  let randomOrder = null;
  function compare(a, b) {
    if (state.sort === "random") {
      if (!randomOrder) randomOrder = new Map(shapes.map((s) => [s.key, Math.random()]));
      return randomOrder.get(a.key) - randomOrder.get(b.key);
    }
    const va = value(a, state.sort), vb = value(b, state.sort);
    if (va === null && vb === null) return value(a, "index") - value(b, "index");
    if (va === null) return 1; // missing values last, in both directions
    if (vb === null) return -1;
    let c = va < vb ? -1 : va > vb ? 1 : 0;
    if (state.desc) c = -c;
    return c || value(a, "index") - value(b, "index");
  }

  function render() {
    state.visible = shapes.filter(matches).sort(compare);
    const grid = $("grid");
    grid.replaceChildren(...state.visible.map(card));
    $("empty").hidden = state.visible.length > 0;
    $("count").textContent = state.visible.length + " of " + shapes.length + " shapes shown" +
      (READONLY ? " · read-only gallery" : "");
    saveState();
  }

  // ------------------------------------------------------------------ cards

  function card(s) {
    const pic = h("div", { class: "pic", title: "Open " + short(s.key), onclick: () => openDetail(s.key) });
    if (s.thumb) {
      pic.append(h("img", { src: s.thumb, alt: "shape " + short(s.key), loading: "lazy", width: 256, height: 256 }));
    } else {
      pic.append(h("span", { class: "nopic", text: "no picture" }));
    }
    if (s.rejected) pic.append(h("span", { class: "flag bad", title: s.rejected, text: "rejected" }));
    else if (s.duplicate_of) pic.append(h("span", { class: "flag", text: "dup of " + short(s.duplicate_of) }));
    if (s.turntable) {
      pic.addEventListener("mouseenter", () => startSpin(pic, s.turntable));
      pic.addEventListener("mouseleave", () => stopSpin(pic));
    }
    pic.addEventListener("mouseenter", () => setFocus(s.key, false));
    const nums = [
      s.genus === null ? "open" : "genus " + s.genus,
      s.components + (s.components === 1 ? " part" : " parts"),
      kfaces(s.faces || 0) + " faces",
    ].join(" · ");
    const actions = h("span", { class: "act" });
    const star = h("button", {
      class: "star", type: "button", "aria-pressed": String(s.stars > 0),
      title: READONLY ? s.stars + " stars" : s.stars > 0 ? "Remove stars" : "Star",
      "aria-label": "star " + short(s.key), text: s.stars > 1 ? "★" + s.stars : "★",
      onclick: (e) => { e.stopPropagation(); act(s.key, "star", { stars: s.stars > 0 ? 0 : 1 }); },
    });
    const reject = h("button", {
      class: "reject", type: "button", "aria-pressed": String(!!s.rejected),
      title: s.rejected ? "Rejected: " + s.rejected + " (click to restore)" : "Reject…",
      "aria-label": "reject " + short(s.key), text: "✕",
      onclick: (e) => {
        e.stopPropagation();
        if (s.rejected) act(s.key, "unreject");
        else openDetail(s.key, "reject");
      },
    });
    if (READONLY) { star.disabled = true; reject.hidden = true; }
    actions.append(star, reject);
    const url = page3d(s);
    if (url) actions.prepend(h("a", { class: "view3d", href: url, title: "3-D view (Enter)", "aria-label": "3-D view of " + short(s.key), text: "3D" }));
    return h("article", {
      class: "card" + (s.rejected ? " is-rejected" : "") + (s.duplicate_of ? " is-duplicate" : "") +
        (state.focus === s.key ? " focus" : ""),
      "data-key": s.key,
    },
    pic,
    h("div", { class: "meta" },
      h("button", { class: "key", type: "button", title: s.key, text: short(s.key), onclick: () => openDetail(s.key) }),
      actions),
    h("div", { class: "nums", title: nums, text: nums }),
    h("div", { class: "chips" }, ...s.tags.map((t) => h("span", { class: "chip", text: t }))));
  }

  function refreshCard(key) {
    const old = document.querySelector('.card[data-key="' + key + '"]');
    const s = byKey.get(key);
    if (!old) return;
    if (!matches(s) && state.current !== key) { render(); return; }
    old.replaceWith(card(s));
  }

  const spinners = new WeakMap();
  function startSpin(pic, url) {
    let frame = 0;
    const sprite = new Image();
    sprite.onload = () => {
      if (!pic.matches(":hover")) return;
      pic.style.backgroundImage = 'url("' + url + '")';
      pic.classList.add("spinning");
      const timer = setInterval(() => {
        frame = (frame + 1) % FRAMES;
        pic.style.backgroundPosition = (frame * 100) / (FRAMES - 1) + "% 0";
      }, SPIN_MS);
      spinners.set(pic, timer);
    };
    sprite.src = url;
  }
  function stopSpin(pic) {
    clearInterval(spinners.get(pic));
    spinners.delete(pic);
    pic.classList.remove("spinning");
    pic.style.backgroundPosition = "0 0";
  }

  // ------------------------------------------------------------------ detail view

  const viewer = { frame: 0, timer: null, url: null };
  function showFrame(i) {
    viewer.frame = ((i % FRAMES) + FRAMES) % FRAMES;
    $("viewer").style.backgroundPosition = (viewer.frame * 100) / (FRAMES - 1) + "% 0";
    $("frame").value = viewer.frame;
  }
  function play(on) {
    clearInterval(viewer.timer);
    viewer.timer = on ? setInterval(() => showFrame(viewer.frame + 1), 160) : null;
    $("play").textContent = on ? "❚❚" : "▶";
  }

  function openDetail(key, focus) {
    state.current = key;
    fillDetail(key);
    $("detail").hidden = false;
    document.body.style.overflow = "hidden";
    if (location.hash !== "#" + key) history.replaceState(null, "", "#" + key);
    if (focus === "reject" && !READONLY) $("reject-why").focus();
    else $("close").focus();
  }
  function closeDetail() {
    play(false);
    $("detail").hidden = true;
    document.body.style.overflow = "";
    state.current = null;
    history.replaceState(null, "", location.pathname + location.search);
    render(); // shapes curated in the detail view may no longer match the filters
  }
  function step(d) {
    const keys = state.visible.map((s) => s.key);
    const i = keys.indexOf(state.current);
    if (keys.length && i >= 0) openDetail(keys[(i + d + keys.length) % keys.length]);
  }

  function kvRows(table, rows) {
    table.replaceChildren(...rows.map(([k, v]) => h("tr", {}, h("td", { text: k }), h("td", { text: fmt(v) }))));
  }

  function fillDetail(key) {
    const s = byKey.get(key);
    $("detail-title").textContent = s.key;
    $("formula").textContent = s.formula;
    const sp = s.spec || {};
    const params = Object.entries(sp.params || {}).map(([k, v]) => k + "=" + v).join(", ");
    $("spec-line").textContent = "box " + fmt(sp.box) + " · grid " + fmt(sp.grid) + " · level " + fmt(sp.level) +
      (params ? " · " + params : "");
    // viewer
    const v = $("viewer");
    const url = s.turntable || s.thumb;
    v.style.backgroundImage = url ? 'url("' + url + '")' : "none";
    v.style.backgroundSize = s.turntable ? FRAMES * 100 + "% 100%" : "contain";
    $("frame").disabled = !s.turntable;
    $("play").disabled = !s.turntable;
    if (viewer.url !== url) { viewer.url = url; showFrame(0); play(!!s.turntable); }
    // downloads
    const dl = $("downloads");
    dl.replaceChildren();
    if (page3d(s)) dl.append(h("a", { href: page3d(s), class: "view3d-link", text: "3-D view" }));
    if (s.mesh && DATA.meshes) dl.append(h("a", { href: s.mesh, download: s.key + ".ply", text: "Mesh (.ply)" }));
    dl.append(h("button", { type: "button", text: "Spec (.json)", onclick: () => download(s.key + ".json", JSON.stringify(s.spec, null, 2)) }));
    if (s.thumb) dl.append(h("a", { href: s.thumb, download: s.key + ".png", text: "Thumbnail" }));
    if (s.turntable) dl.append(h("a", { href: s.turntable, download: s.key + "-turntable.png", text: "Turntable" }));
    dl.append(h("p", { class: "cmd", title: "Regenerate this shape", text: "surfgen render --from " + DATA.catalogue + " " + short(s.key) + " -o " + short(s.key) + ".ply" }));
    // curation
    const stars = $("stars");
    stars.replaceChildren(...[1, 2, 3, 4, 5].map((n) => h("button", {
      type: "button", class: n <= s.stars ? "on" : "", role: "radio", "aria-checked": String(n === s.stars),
      title: n + (n === 1 ? " star" : " stars"), "aria-label": n + " stars", text: "★", disabled: READONLY,
      onclick: () => act(s.key, "star", { stars: n === s.stars ? 0 : n }),
    })));
    if (!READONLY && s.stars > 0) stars.append(h("button", { type: "button", class: "clear", text: "clear", onclick: () => act(s.key, "star", { stars: 0 }) }));
    $("reject-row").hidden = READONLY;
    $("reject-why").hidden = !!s.rejected;
    $("reject").hidden = !!s.rejected;
    $("unreject").hidden = !s.rejected;
    $("rejected-line").hidden = !s.rejected;
    $("rejected-line").textContent = s.rejected ? "Rejected: " + s.rejected : "";
    const chips = $("detail-tags");
    chips.replaceChildren(...s.tags.map((t) => h("span", { class: "chip" }, t,
      READONLY ? null : h("button", { type: "button", title: "Remove tag " + t, "aria-label": "remove tag " + t, text: "×", onclick: () => act(s.key, "untag", { tags: [t] }) }))));
    if (READONLY && !s.tags.length) chips.append(h("span", { class: "hint", text: "no tags" }));
    $("note").value = s.note || "";
    $("note").readOnly = READONLY;
    if (READONLY) $("note").hidden = !s.note;
    const dup = $("dup-line");
    dup.hidden = !s.duplicate_of;
    dup.replaceChildren();
    if (s.duplicate_of) {
      dup.append("Near duplicate of ");
      dup.append(byKey.has(s.duplicate_of)
        ? h("a", { href: "#" + s.duplicate_of, text: short(s.duplicate_of), onclick: (e) => { e.preventDefault(); openDetail(s.duplicate_of); } })
        : short(s.duplicate_of));
    }
    // metrics and provenance
    const m = s.metrics || {};
    kvRows($("metrics"), [
      ["genus", s.genus], ["components", s.components], ["Euler characteristic", s.euler],
      ["faces", s.faces], ["vertices", s.vertices], ["area", s.area], ["volume", s.volume],
      ["box fraction", m.box_fraction], ["largest component", m.largest_component_fraction],
      ["total curvature", m.total_curvature], ["watertight", m.watertight], ["non-finite samples", m.nonfinite],
      ["d", s.d], ["solidity", m.solidity],
      // the surface again on the nested grid twice as fine (filters/resolution.py)
      ["resolution shift (cells, p95)", m.resolution_shift],
      ["… to fine / to coarse", m.resolution_shift === undefined ? undefined : fmt(m.resolution_to_fine) + " / " + fmt(m.resolution_to_coarse)],
      ["fine area / area", m.resolution_area],
    ]);
    const p = s.provenance || {};
    const run = (DATA.runs || {})[String(s.run)] || {};
    const versions = Object.entries(run.versions || {}).map(([k, v]) => k + " " + v).join(", ");
    kvRows($("provenance"), [
      ["run", s.run + (run.status ? " (" + run.status + ")" : "")], ["index", s.index], ["seed", p.seed],
      ["sampler version", p.sampler], ["config", p.config], ["started", run.started],
      ["versions", versions || null], ["verdict", s.verdict + (s.reasons.length ? ": " + s.reasons.join(", ") : "")],
    ]);
    $("spec").textContent = JSON.stringify(s.spec, null, 1);
  }

  function download(name, text, type) {
    const a = h("a", { href: URL.createObjectURL(new Blob([text], { type: type || "application/json" })), download: name });
    document.body.append(a);
    a.click();
    setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 0);
  }

  async function copyFormula() {
    const text = $("formula").textContent;
    try {
      await navigator.clipboard.writeText(text);
    } catch (e) { // no clipboard API (e.g. a file:// page): select and copy the old way
      const range = document.createRange();
      range.selectNodeContents($("formula"));
      const sel = window.getSelection();
      sel.removeAllRanges();
      sel.addRange(range);
      document.execCommand("copy");
    }
    $("copied").hidden = false;
    setTimeout(() => { $("copied").hidden = true; }, 1500);
  }

  // ------------------------------------------------------------------ tools

  function renderTagOptions() {
    const counts = new Map();
    for (const s of shapes) for (const t of s.tags) counts.set(t, (counts.get(t) || 0) + 1);
    const sel = $("tag");
    const keep = sel.value;
    sel.replaceChildren(h("option", { value: "", text: "any tag" }),
      ...[...counts.keys()].sort().map((t) => h("option", { value: t, text: t + " (" + counts.get(t) + ")" })));
    sel.value = counts.has(keep) ? keep : "";
  }

  function renderFamilyOptions() {
    const counts = new Map();
    for (const s of shapes) counts.set(s.family, (counts.get(s.family) || 0) + 1);
    const sel = $("family");
    sel.replaceChildren(h("option", { value: "", text: "any family" }),
      ...[...counts.keys()].sort().map((f) => h("option", { value: f, text: f + " (" + counts.get(f) + ")" })));
    sel.value = counts.has(state.family) ? state.family : "";
    state.family = sel.value;
  }

  async function applyWhere() {
    const text = $("where").value.trim();
    const err = $("where-error");
    if (!text) { state.whereKeys = null; err.hidden = true; render(); return; }
    try {
      const data = await api("shapes?where=" + encodeURIComponent(text) + "&keys=1");
      state.whereKeys = new Set(data.keys);
      err.hidden = true;
    } catch (e) {
      err.textContent = e.message;
      err.hidden = false;
      return;
    }
    render();
  }

  function exportZip() {
    const form = h("form", { method: "post", action: "api/export" },
      h("input", { type: "hidden", name: "keys", value: state.visible.map((s) => s.key).join(",") }));
    document.body.append(form);
    form.submit();
    form.remove();
  }

  function saveState() {
    try {
      sessionStorage.setItem("surfgen-gallery", JSON.stringify({
        sort: state.sort, desc: state.desc, tag: state.tag, family: state.family, starred: state.starred,
        showRejected: state.showRejected, showDuplicates: state.showDuplicates,
      }));
    } catch (e) { /* storage may be off for file:// pages */ }
  }
  function loadState() {
    try { Object.assign(state, JSON.parse(sessionStorage.getItem("surfgen-gallery") || "{}")); } catch (e) { /* ignore */ }
  }

  // ------------------------------------------------------------------ keyboard curation

  function setFocus(key, scroll) {
    if (state.focus === key) return;
    for (const el of document.querySelectorAll(".card.focus")) el.classList.remove("focus");
    state.focus = key;
    const el = key && document.querySelector('.card[data-key="' + key + '"]');
    if (el) {
      el.classList.add("focus");
      if (scroll) el.scrollIntoView({ block: "nearest" });
    }
  }
  function moveFocus(d) {
    const keys = state.visible.map((s) => s.key);
    if (!keys.length) return;
    const i = keys.indexOf(state.focus);
    setFocus(keys[i < 0 ? (d > 0 ? 0 : keys.length - 1) : (i + d + keys.length) % keys.length], true);
  }
  // s star (or remove the stars), r reject (asks why; restores a rejected shape), t tag (asks).
  function curateKey(key, k) {
    const s = byKey.get(key);
    if (!s || READONLY) return;
    if (k === "s") act(key, "star", { stars: s.stars > 0 ? 0 : 1 });
    else if (k === "r") {
      if (s.rejected) { act(key, "unreject"); return; }
      const why = window.prompt("Why reject " + short(key) + "?");
      if (why && why.trim()) act(key, "reject", { why: why.trim() });
    } else if (k === "t") {
      const tags = (window.prompt("Tags for " + short(key) + " (separated by spaces)") || "").split(/[\s,]+/).filter(Boolean);
      if (tags.length) act(key, "tag", { tags: tags });
    }
  }
  function onKey(e) {
    const typing = ["INPUT", "TEXTAREA", "SELECT"].includes(document.activeElement.tagName);
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    if (!$("detail").hidden) {
      if (e.key === "Escape") closeDetail();
      else if (typing) return;
      else if (e.key === "ArrowLeft") step(-1);
      else if (e.key === "ArrowRight") step(1);
      else if ("srt".includes(e.key) && e.key.length === 1) curateKey(state.current, e.key);
      return;
    }
    if (typing) return;
    if (e.key === "ArrowRight") { e.preventDefault(); moveFocus(1); }
    else if (e.key === "ArrowLeft") { e.preventDefault(); moveFocus(-1); }
    else if (e.key === "Enter" && state.focus) {
      const url = page3d(byKey.get(state.focus));
      if (url) location.href = url; else openDetail(state.focus);
    } else if (e.key === " " && state.focus) { e.preventDefault(); openDetail(state.focus); }
    else if (state.focus && e.key.length === 1 && "srt".includes(e.key)) curateKey(state.focus, e.key);
  }

  function init() {
    loadState();
    const sort = $("sort");
    sort.replaceChildren(...SORTS.map(([v, label]) => h("option", { value: v, text: label })));
    sort.value = state.sort;
    $("direction").textContent = state.desc ? "↓" : "↑";
    $("starred").checked = state.starred;
    $("show-rejected").checked = state.showRejected;
    $("show-duplicates").checked = state.showDuplicates;
    renderTagOptions();
    $("tag").value = state.tag;
    renderFamilyOptions();
    $("family").addEventListener("change", (e) => { state.family = e.target.value; render(); });
    sort.addEventListener("change", () => { state.sort = sort.value; randomOrder = null; render(); });
    $("direction").addEventListener("click", () => {
      state.desc = !state.desc;
      $("direction").textContent = state.desc ? "↓" : "↑";
      render();
    });
    $("tag").addEventListener("change", (e) => { state.tag = e.target.value; render(); });
    $("search").addEventListener("input", (e) => { state.search = e.target.value; render(); });
    $("starred").addEventListener("change", (e) => { state.starred = e.target.checked; render(); });
    $("show-rejected").addEventListener("change", (e) => { state.showRejected = e.target.checked; render(); });
    $("show-duplicates").addEventListener("change", (e) => { state.showDuplicates = e.target.checked; render(); });
    $("export-list").addEventListener("click", () => download("surfgen-shapes.json", JSON.stringify(state.visible, null, 1)));
    if (!READONLY) {
      $("where-apply").addEventListener("click", applyWhere);
      $("where").addEventListener("keydown", (e) => { if (e.key === "Enter") { e.preventDefault(); applyWhere(); } });
      $("where-help").addEventListener("click", (e) => {
        e.preventDefault();
        const err = $("where-error");
        err.className = "hint";
        err.replaceChildren("Fields: ", h("ul", { class: "help-list" },
          ...Object.entries(DATA.where_fields).map(([k, v]) => h("li", {}, h("code", { text: k }), " – " + v))),
        "Operators: = != < <= > >= ~ (contains); combine with and, or, not, parentheses.");
        err.hidden = !err.hidden;
      });
      $("export-zip").addEventListener("click", exportZip);
      $("reject").addEventListener("click", () => {
        const why = $("reject-why").value.trim();
        if (!why) { toast("say why you reject it", true); $("reject-why").focus(); return; }
        $("reject-why").value = "";
        act(state.current, "reject", { why: why });
      });
      $("reject-why").addEventListener("keydown", (e) => { if (e.key === "Enter") $("reject").click(); });
      $("unreject").addEventListener("click", () => act(state.current, "unreject"));
      $("add-tag").addEventListener("keydown", (e) => {
        if (e.key !== "Enter") return;
        const tags = e.target.value.split(/[\s,]+/).filter(Boolean);
        e.target.value = "";
        if (tags.length) act(state.current, "tag", { tags: tags });
      });
      $("save-note").addEventListener("click", () => act(state.current, "note", { note: $("note").value }));
    }
    $("copy-formula").addEventListener("click", copyFormula);
    $("close").addEventListener("click", closeDetail);
    $("prev").addEventListener("click", () => step(-1));
    $("next").addEventListener("click", () => step(1));
    $("detail").addEventListener("click", (e) => { if (e.target === $("detail")) closeDetail(); });
    $("play").addEventListener("click", () => play(!viewer.timer));
    $("frame").addEventListener("input", (e) => { play(false); showFrame(Number(e.target.value)); });
    const v = $("viewer");
    let drag = null;
    v.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, f: viewer.frame }; play(false); v.classList.add("dragging"); v.setPointerCapture(e.pointerId); });
    v.addEventListener("pointermove", (e) => { if (drag) showFrame(drag.f - Math.round((e.clientX - drag.x) / 25)); });
    v.addEventListener("pointerup", () => { drag = null; v.classList.remove("dragging"); });
    document.addEventListener("keydown", onKey);
    render();
    const hashKey = location.hash.slice(1);
    if (byKey.has(hashKey)) openDetail(hashKey);
    document.body.dataset.ready = "1";
  }

  init();
})();
