/* surfgen 3-D viewer: a shape's detail page.
 *
 * Shows the thumbnail as a poster, then loads the mesh (GLB) lazily and draws it with three.js
 * (vendored, npm 0.180.0, one classic-script bundle so the page also works from file://):
 * orbit, zoom, reset, wireframe, flat/smooth shading, statistics. Live pages (`surfgen serve`) also
 * have sliders that ask the server to re-evaluate the shape (POST api/explore) and replace the
 * mesh, "Save as new shape", and keyboard curation (s star, r reject, t tag, ←/→ previous/next).
 * The canvas gets data-rendered="true" once it has drawn a mesh (tests wait for it).
 * User text only ever reaches the page through textContent.
 */
(function () {
  "use strict";

  const $ = (id) => document.getElementById(id);
  const DATA = JSON.parse($("shape-data").textContent);
  const LIVE = DATA.mode === "live";
  const SHAPE = DATA.shape;
  const { THREE, OrbitControls, GLTFLoader } = window.SURFGEN_THREE;
  const canvas = $("viewer");

  // ------------------------------------------------------------------ helpers

  const { h, fmt } = window.SURFGEN_UI;
  const toast = window.SURFGEN_UI.toaster(2200, 6000);
  const api = window.SURFGEN_UI.apiAt("../api/");

  // ------------------------------------------------------------------ the scene

  const renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  renderer.setClearColor(0xf6f6f4, 1);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(30, 1, 0.01, 1e6);
  camera.up.set(0, 0, 1); // surfgen's z is up, as in the thumbnails
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404550, 0.9));
  const key = new THREE.DirectionalLight(0xffffff, 1.5);
  key.position.set(-0.5, 0.6, 1.0);
  const fill = new THREE.DirectionalLight(0xffffff, 0.5);
  fill.position.set(0.8, -0.2, 0.4);
  camera.add(key, fill); // lights move with the camera: the lit side is always the one seen
  scene.add(camera);
  const front = new THREE.MeshStandardMaterial({
    vertexColors: true, roughness: 0.55, metalness: 0.0, side: THREE.FrontSide,
    polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
  });
  const back = new THREE.MeshStandardMaterial({
    color: 0x9c92b2, roughness: 0.7, side: THREE.BackSide, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
  });
  const wire = new THREE.MeshBasicMaterial({ color: 0x22252a, wireframe: true, transparent: true, opacity: 0.28 });
  const group = new THREE.Group();
  scene.add(group);
  const controls = new OrbitControls(camera, canvas);
  controls.zoomSpeed = 1.2;
  controls.addEventListener("change", draw);

  const view = { geometry: null, box: null, fitted: false, faces: 0 };
  let drawQueued = false;
  function draw() {
    if (drawQueued) return;
    drawQueued = true;
    requestAnimationFrame(() => {
      drawQueued = false;
      resize();
      renderer.render(scene, camera);
      if (view.geometry) {
        canvas.dataset.rendered = "true";
        canvas.dataset.faces = String(view.faces);
      }
    });
  }
  function resize() {
    const w = canvas.clientWidth, hgt = canvas.clientHeight;
    if (canvas.width !== Math.round(w * renderer.getPixelRatio()) || canvas.height !== Math.round(hgt * renderer.getPixelRatio())) {
      renderer.setSize(w, hgt, false);
      camera.aspect = w / Math.max(hgt, 1);
      camera.updateProjectionMatrix();
    }
  }
  window.addEventListener("resize", draw);

  // Height colours (z through the box), close to the thumbnails' palette.
  const STOPS = [[0.0, [0.23, 0.42, 0.62]], [0.35, [0.42, 0.66, 0.70]], [0.65, [0.90, 0.80, 0.55]], [1.0, [0.86, 0.47, 0.36]]];
  function heightColours(geometry, zlo, zhi) {
    const pos = geometry.getAttribute("position");
    const colours = new Float32Array(pos.count * 3);
    const span = zhi - zlo || 1;
    for (let i = 0; i < pos.count; i++) {
      const t = Math.min(1, Math.max(0, (pos.getZ(i) - zlo) / span));
      let k = 1;
      while (k < STOPS.length - 1 && STOPS[k][0] < t) k++;
      const [t0, c0] = STOPS[k - 1], [t1, c1] = STOPS[k];
      const u = (t - t0) / (t1 - t0 || 1);
      // The stops are sRGB; the renderer works in linear light.
      for (let j = 0; j < 3; j++) colours[3 * i + j] = Math.pow(c0[j] + u * (c1[j] - c0[j]), 2.2);
    }
    geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
  }

  function fit(box, geometry) {
    // Frame the mesh's bounding sphere (the box's when empty); explore steps keep this framing
    // until the box changes, so a slider's effect is seen against a still camera.
    let centre, radius;
    if (geometry) {
      geometry.computeBoundingSphere();
      centre = geometry.boundingSphere.center.clone();
      radius = geometry.boundingSphere.radius || 1;
    } else {
      const lo = new THREE.Vector3(box[0], box[2], box[4]), hi = new THREE.Vector3(box[1], box[3], box[5]);
      centre = lo.clone().add(hi).multiplyScalar(0.5);
      radius = hi.clone().sub(lo).length() / 2;
    }
    const dist = radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.02;
    const dir = view.fitted ? camera.position.clone().sub(controls.target).normalize()
      : new THREE.Vector3(Math.cos(0.44) * Math.cos(0.52), Math.cos(0.44) * Math.sin(0.52), Math.sin(0.44));
    controls.target.copy(centre);
    camera.position.copy(centre).addScaledVector(dir, dist);
    camera.near = dist / 100;
    camera.far = dist * 100;
    camera.updateProjectionMatrix();
    controls.update();
    if (!view.fitted) controls.saveState();
    view.fitted = true;
    view.box = box.slice();
  }

  function showGeometry(geometry, box) {
    group.clear();
    if (view.geometry) view.geometry.dispose();
    view.geometry = geometry;
    view.faces = geometry ? (geometry.index ? geometry.index.count / 3 : geometry.getAttribute("position").count / 3) : 0;
    if (geometry) {
      geometry.computeVertexNormals();
      geometry.computeBoundingBox();
      heightColours(geometry, geometry.boundingBox.min.z, geometry.boundingBox.max.z);
      group.add(new THREE.Mesh(geometry, front), new THREE.Mesh(geometry, back));
      const w = new THREE.Mesh(geometry, wire);
      w.visible = $("wireframe").checked;
      w.name = "wire";
      group.add(w);
    }
    if (!view.fitted || JSON.stringify(box) !== JSON.stringify(view.box)) fit(box, geometry);
    const poster = $("poster");
    if (poster) poster.hidden = true;
    $("loading").hidden = !!geometry;
    if (!geometry) $("loading").textContent = "no surface in the box";
    canvas.classList.add("ready");
    draw();
  }

  const loader = new GLTFLoader();
  function parseGlb(buffer, box) {
    return new Promise((resolve, reject) => {
      loader.parse(buffer, "", (gltf) => {
        let geometry = null;
        gltf.scene.traverse((o) => { if (!geometry && o.isMesh) geometry = o.geometry; });
        showGeometry(geometry, box);
        resolve(geometry);
      }, (err) => reject(err instanceof Error ? err : new Error(String(err && err.message || err))));
    });
  }

  function base64ToBuffer(text) {
    const bin = atob(text);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out.buffer;
  }

  // ------------------------------------------------------------------ statistics

  function showStats(st, box) {
    $("face-count").textContent = fmt(st.faces);
    $("vertex-count").textContent = fmt(st.vertices);
    $("stat-components").textContent = fmt(st.components);
    $("stat-euler").textContent = fmt(st.euler);
    $("stat-genus").textContent = st.genus === null || st.genus === undefined ? "– (open)" : fmt(st.genus);
    const bbox = st.bbox || box;
    if (bbox) $("stat-bbox").textContent = fmt(bbox);
  }
  function specLine(spec) {
    const params = Object.entries(spec.params || {}).map(([k, v]) => k + "=" + fmt(v, 6)).join(", ");
    $("spec-line").textContent = "box " + fmt(spec.box) + " · grid " + spec.grid.join("×") + " · level " + fmt(spec.level) +
      (params ? " · " + params : "") + (DATA.cap ? " · capped" : "");
  }

  // ------------------------------------------------------------------ the catalogued shape

  function fillShape() {
    const s = SHAPE;
    const m = s.metrics || {};
    showStats({ faces: s.faces, vertices: s.vertices, components: s.components, euler: s.euler, genus: s.genus }, m.bbox);
    const rows = (table, pairs) => table.replaceChildren(...pairs.map(([k, v]) => h("tr", {}, h("td", { text: k }), h("td", { text: fmt(v) }))));
    rows($("metrics"), [
      ["area", s.area], ["volume", s.volume], ["box fraction", m.box_fraction],
      ["largest component", m.largest_component_fraction], ["total curvature", m.total_curvature],
      ["watertight", m.watertight], ["non-finite samples", m.nonfinite], ["d", s.d],
      ["solidity", m.solidity],
      // the surface again on the nested grid twice as fine (filters/resolution.py)
      ["resolution shift (cells, p95)", m.resolution_shift],
      ["… to fine / to coarse", m.resolution_shift === undefined ? undefined : fmt(m.resolution_to_fine) + " / " + fmt(m.resolution_to_coarse)],
      ["fine area / area", m.resolution_area],
    ]);
    const p = s.provenance || {};
    rows($("provenance"), [
      ["run", s.run], ["index", s.index], ["seed", p.seed], ["derived from", p.derived_from],
      ["changes", p.changes], ["verdict", s.verdict + (s.reasons && s.reasons.length ? ": " + s.reasons.join(", ") : "")],
    ]);
    curationLine();
  }
  function curationLine() {
    const s = SHAPE;
    const bits = [s.stars > 0 ? "★".repeat(s.stars) : "no stars", "tags: " + (s.tags.length ? s.tags.join(", ") : "–")];
    if (s.rejected) bits.push("rejected: " + s.rejected);
    if (s.note) bits.push("note: " + s.note);
    $("curation-line").textContent = bits.join(" · ");
    $("curation-line").className = s.rejected ? "rejected-line" : "";
  }

  // ------------------------------------------------------------------ loading the mesh

  function loadMesh() {
    const box = DATA.spec.box;
    if (!SHAPE) { exploreNow(); return; }
    if (!LIVE) {
      window.SURFGEN_MESH_LOADED = (k, text) => {
        if (k === SHAPE.key) parseGlb(base64ToBuffer(text), box).catch(failed);
      };
      document.head.append(h("script", { src: SHAPE.key + ".glb.js", onerror: () => failed(new Error("mesh file missing")) }));
      return;
    }
    fetch("../api/shape/" + SHAPE.key + "/mesh.glb")
      .then((res) => { if (!res.ok) throw new Error("mesh: " + res.status + " " + res.statusText); return res.arrayBuffer(); })
      .then((buf) => parseGlb(buf, box))
      .catch(failed);
  }
  function failed(err) {
    $("loading").textContent = "cannot show the mesh: " + err.message;
    $("loading").hidden = false;
  }

  // ------------------------------------------------------------------ explore

  const explore = { changes: {}, inFlight: false, pending: false, source: DATA.source, last: null };

  function buildSliders(knobs) {
    const box = $("sliders");
    if (!box) return;
    box.replaceChildren();
    const main = knobs.filter((k) => k.kind !== "literal");
    const literals = knobs.filter((k) => k.kind === "literal");
    for (const k of main) box.append(slider(k));
    if (literals.length) {
      const more = h("details", { class: "literals" }, h("summary", { text: "numbers in the formula (" + literals.length + ")" }));
      for (const k of literals) more.append(slider(k));
      box.append(more);
    }
  }
  function slider(k) {
    const id = "knob-" + k.name.replace(/[^A-Za-z0-9_]/g, "_");
    const lo = Math.min(k.lo, k.value), hi = Math.max(k.hi, k.value);
    const input = h("input", { type: "range", id: id, min: lo, max: hi, step: k.step, value: k.value, "data-knob": k.name, "aria-label": k.label });
    const out = h("output", { for: id, text: fmt(k.value, 5) });
    input.addEventListener("input", () => {
      const v = Number(input.value);
      out.textContent = fmt(v, 5);
      if (v === k.value) delete explore.changes[k.name]; else explore.changes[k.name] = v;
      schedule();
    });
    input.addEventListener("keydown", (e) => e.stopPropagation()); // arrows move the slider, not the page
    return h("div", { class: "knob", title: k.hint || "" },
      h("label", { for: id, class: "knob-name", text: k.label }), input, out,
      k.kind === "literal" ? h("span", { class: "knob-hint", text: k.hint }) : null);
  }

  function schedule() {
    if (explore.inFlight) { explore.pending = true; return; }
    exploreNow();
  }
  async function exploreNow() {
    explore.inFlight = true;
    explore.pending = false;
    const body = Object.assign({}, explore.source, { changes: explore.changes });
    if (DATA.cap !== undefined && !("key" in explore.source)) body.cap = DATA.cap;
    const status = $("explore-status");
    const started = performance.now();
    try {
      const res = await api("explore", body);
      const buf = await fetch("../" + res.mesh).then((r) => { if (!r.ok) throw new Error("mesh " + r.status); return r.arrayBuffer(); });
      // Shown even if the slider has moved on (it is newer than what is on screen); the
      // newest position is asked for next, so a continuous drag keeps the view moving.
      await parseGlb(buf, res.box);
      showStats(res.stats, null);
      $("formula").textContent = res.formula;
      specLine({ box: res.box, grid: res.grid, level: res.level, params: res.params });
      if (status) {
        status.textContent = fmt(res.faces) + " faces · grid " + res.grid.join("×") + " · server " +
          Math.round(res.seconds * 1000) + " ms (evaluate " + Math.round(res.timings.evaluate * 1000) + ", mesh " +
          Math.round(res.timings.mesh * 1000) + ", glb " + Math.round(res.timings.glb * 1000) + ") · round trip " +
          Math.round(performance.now() - started) + " ms" + (res.empty ? " · " + res.empty : "");
        status.className = "hint";
      }
      explore.last = res;
      // Topology (components, genus) costs as much as the GLB: ask once the sliders rest.
      fetchTopology(res);
      const save = $("save-variant");
      if (save) save.disabled = Object.keys(explore.changes).length === 0;
    } catch (err) {
      if (status) { status.textContent = err.message; status.className = "error"; }
    } finally {
      explore.inFlight = false;
      if (explore.pending) exploreNow();
    }
  }

  function fetchTopology(res) {
    for (const id of ["stat-components", "stat-euler", "stat-genus"]) $(id).textContent = "…";
    setTimeout(async () => {
      if (explore.last !== res || explore.inFlight) return; // a newer step will ask again
      try {
        const st = (await api(res.topology.replace(/^api\//, ""))).stats;
        if (explore.last === res) showStats(st, null);
      } catch (err) { /* the step is gone from the server's cache: a newer one replaced it */ }
    }, 250);
  }

  async function saveVariant() {
    const btn = $("save-variant");
    btn.disabled = true;
    try {
      const res = await api("explore/save", { key: SHAPE.key, changes: explore.changes });
      const line = $("saved-line");
      line.replaceChildren("Saved as ", h("a", { href: "../" + res.url, id: "saved-link", text: res.shape.key }),
        " (derived from " + SHAPE.key.slice(0, 8) + ")");
      line.hidden = false;
      toast("saved as a new shape");
    } catch (err) {
      toast(err.message, true);
    } finally {
      btn.disabled = Object.keys(explore.changes).length === 0;
    }
  }

  function undoChanges() {
    explore.changes = {};
    buildSliders(DATA.knobs);
    schedule();
  }

  // ------------------------------------------------------------------ curation by keyboard

  async function curate(action, body, done) {
    try {
      const res = await api("shapes/" + SHAPE.key + "/" + action, body);
      Object.assign(SHAPE, res.shape);
      curationLine();
      toast(done);
    } catch (err) {
      toast(err.message, true);
    }
  }
  function go(k) {
    if (!k) return;
    location.href = LIVE ? "../shape/" + k : k + ".html";
  }
  function onKey(e) {
    const el = document.activeElement;
    const tag = el ? el.tagName : "";
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    if (["TEXTAREA", "SELECT"].includes(tag) || (tag === "INPUT" && el.type !== "range" && el.type !== "checkbox")) return;
    if (e.key === "ArrowLeft") { e.preventDefault(); go(DATA.prev); return; }
    if (e.key === "ArrowRight") { e.preventDefault(); go(DATA.next); return; }
    if (e.key === "Escape") { location.href = $("back").getAttribute("href"); return; }
    if (e.key === "0") { controls.reset(); return; }
    if (!LIVE || !SHAPE) return;
    if (e.key === "s") {
      curate("star", { stars: SHAPE.stars > 0 ? 0 : 1 }, SHAPE.stars > 0 ? "stars removed" : "starred");
    } else if (e.key === "r") {
      if (SHAPE.rejected) {
        if (window.confirm("Restore this shape (rejected: " + SHAPE.rejected + ")?")) curate("unreject", {}, "restored");
        return;
      }
      const why = window.prompt("Why reject this shape?");
      if (why && why.trim()) curate("reject", { why: why.trim() }, "rejected");
    } else if (e.key === "t") {
      const text = window.prompt("Tags to add (separated by spaces)");
      const tags = (text || "").split(/[\s,]+/).filter(Boolean);
      if (tags.length) curate("tag", { tags: tags }, "tagged");
    }
  }

  // ------------------------------------------------------------------ wiring

  function init() {
    $("formula").textContent = DATA.spec.formula;
    specLine(DATA.spec);
    if (SHAPE) fillShape();
    if (DATA.prev) { $("prev").hidden = false; $("prev").href = LIVE ? "../shape/" + DATA.prev : DATA.prev + ".html"; }
    if (DATA.next) { $("next").hidden = false; $("next").href = LIVE ? "../shape/" + DATA.next : DATA.next + ".html"; }
    if (!LIVE && SHAPE) $("back").href = "../index.html#" + SHAPE.key;
    $("reset-view").addEventListener("click", () => controls.reset());
    $("wireframe").addEventListener("change", (e) => {
      const w = group.getObjectByName("wire");
      if (w) w.visible = e.target.checked;
      draw();
    });
    $("shading").addEventListener("change", (e) => {
      front.flatShading = back.flatShading = e.target.value === "flat";
      front.needsUpdate = back.needsUpdate = true;
      draw();
    });
    let spinning = null;
    $("spin").addEventListener("change", (e) => {
      cancelAnimationFrame(spinning);
      controls.autoRotate = e.target.checked;
      const loop = () => { controls.update(); spinning = requestAnimationFrame(loop); };
      if (e.target.checked) loop();
    });
    if (LIVE) {
      buildSliders(DATA.knobs);
      $("reset-changes").addEventListener("click", undoChanges);
      if ($("save-variant")) $("save-variant").addEventListener("click", saveVariant);
      const apply = $("formula-apply");
      if (apply) {
        const fromPreset = () => { if ($("preset").value) location.href = "?preset=" + encodeURIComponent($("preset").value); };
        $("preset").addEventListener("change", fromPreset);
        const fromFormula = () => {
          const f = $("formula-input").value.trim();
          if (f) location.href = "?formula=" + encodeURIComponent(f);
        };
        apply.addEventListener("click", fromFormula);
        $("formula-input").addEventListener("keydown", (e) => { if (e.key === "Enter") fromFormula(); });
        if (explore.source.preset) $("preset").value = explore.source.preset;
        if (explore.source.formula) $("formula-input").value = explore.source.formula;
      }
    }
    document.addEventListener("keydown", onKey);
    draw();
    // The poster is up; fetch the mesh once the page itself has loaded.
    if (document.readyState === "complete") setTimeout(loadMesh, 0);
    else window.addEventListener("load", () => setTimeout(loadMesh, 0));
    document.body.dataset.ready = "1";
  }

  init();
})();
