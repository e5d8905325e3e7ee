// viewdb's web page: upload a photo to POST /query and show the answer; browse GET /objects.
// Plain JavaScript, no build step. Every request carries the bearer token once the
// server has asked for it (a 401); pictures are fetched with it and shown as blob URLs.
"use strict";

const TOKEN_KEY = "viewdb-token";
const state = {
  token: localStorage.getItem(TOKEN_KEY) || "",
  info: null,
  pictures: new Map(), // URL -> blob: URL
  catalogueLoaded: false,
  retry: null, // what to do again once a token is given
  turntable: null,
  selected: null, // the result whose overlay is shown
};

const $ = (id) => document.getElementById(id);

class NeedsToken extends Error {}

class Refused extends Error {
  constructor(message, status) {
    super(message);
    this.status = status;
  }
}

function el(tag, props = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(props)) {
    if (key === "class") node.className = value;
    else if (key === "text") node.textContent = value;
    else if (key === "style") Object.assign(node.style, value); // CSSOM: allowed by the page's CSP
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value);
  }
  for (const child of children) if (child != null) node.append(child);
  return node;
}

// ------------------------------------------------------------------ requests
async function errorText(response) {
  try {
    const body = await response.json();
    if (body && body.error) return body.error;
  } catch (_) { /* not JSON */ }
  return `${response.status} ${response.statusText}`.trim();
}

async function api(path, options = {}) {
  const headers = Object.assign({}, options.headers || {});
  if (state.token) headers.Authorization = `Bearer ${state.token}`;
  const response = await fetch(path, Object.assign({}, options, { headers }));
  if (response.status === 401) {
    const why = await errorText(response);
    askForToken(state.token ? `The server refused that token: ${why}` : "");
    throw new NeedsToken(why);
  }
  if (!response.ok) throw new Refused(await errorText(response), response.status);
  return response;
}

async function picture(url) {
  if (state.pictures.has(url)) return state.pictures.get(url);
  const blob = await (await api(url)).blob();
  const local = URL.createObjectURL(blob);
  state.pictures.set(url, local);
  return local;
}

function showPicture(img, url) {
  picture(url).then((src) => { img.src = src; }).catch((error) => {
    if (!(error instanceof NeedsToken)) img.alt = `No picture: ${error.message}`;
  });
}

// ------------------------------------------------------------------ token
function askForToken(message) {
  $("token-panel").hidden = false;
  $("query-panel").hidden = true;
  $("catalogue-panel").hidden = true;
  $("token-message").textContent = message;
  $("token").focus();
}

$("token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  state.token = $("token").value.trim();
  localStorage.setItem(TOKEN_KEY, state.token);
  $("token-panel").hidden = true;
  showTab(currentTab());
  const again = state.retry || start;
  state.retry = null;
  again();
});

// ------------------------------------------------------------------ tabs
function currentTab() {
  const pressed = document.querySelector('.tab[aria-pressed="true"]');
  return pressed ? pressed.dataset.tab : "query";
}

function showTab(tab) {
  for (const button of document.querySelectorAll(".tab")) {
    button.setAttribute("aria-pressed", String(button.dataset.tab === tab));
  }
  if (!$("token-panel").hidden) return;
  $("query-panel").hidden = tab !== "query";
  $("catalogue-panel").hidden = tab !== "catalogue";
  if (tab === "catalogue" && !state.catalogueLoaded) loadCatalogue();
}

for (const button of document.querySelectorAll(".tab")) {
  button.addEventListener("click", () => showTab(button.dataset.tab));
}

// ------------------------------------------------------------------ start
async function start() {
  try {
    state.info = await (await api("info")).json();
    const limit = state.info.limits.max_image_body;
    $("server").textContent = `${state.info.objects.length} objects, grid ${state.info.gap}°, ` +
      `photos up to ${megabytes(limit)} · viewdb ${state.info.viewdb}`;
    $("k").max = String(Math.min(10, state.info.limits.max_k));
  } catch (error) {
    if (!(error instanceof NeedsToken)) {
      $("server").textContent = `The server did not answer: ${error.message}`;
      state.retry = start;
    } else {
      state.retry = start;
    }
  }
}

function megabytes(bytes) {
  if (bytes < 1048576) return `${Math.max(1, Math.round(bytes / 1024))} kB`;
  return `${(bytes / 1048576).toFixed(bytes >= 10485760 ? 0 : 1)} MB`;
}

// ------------------------------------------------------------------ query
function say(text, isError = false) {
  const message = $("message");
  message.hidden = !text;
  message.textContent = text;
  message.className = isError ? "error" : "";
  message.setAttribute("role", isError ? "alert" : "status");
}

$("query-form").addEventListener("submit", (event) => {
  event.preventDefault();
  recognise();
});

async function recognise() {
  const file = $("photo").files[0];
  if (!file) {
    say("Choose or take a photo first.", true);
    return;
  }
  const form = new FormData();
  form.append("photo", file, file.name || "photo.jpg");
  form.append("plan", $("plan").value);
  form.append("k", $("k").value || "3");
  $("go").disabled = true;
  $("result").hidden = true;
  say(`Recognising ${file.name || "the photo"} (${megabytes(file.size)})…`);
  const started = performance.now();
  try {
    const response = await api("query", { method: "POST", body: form });
    const answer = await response.json();
    say("");
    showAnswer(answer, performance.now() - started);
  } catch (error) {
    if (error instanceof NeedsToken) {
      state.retry = recognise;
    } else if (error instanceof Refused && error.status === 413) {
      say(`${file.name || "The photo"} is too large for this server: ${error.message}.`, true);
    } else if (error instanceof TypeError) {
      // fetch itself failed: no reply at all (server gone, or the upload cut off)
      const limit = state.info ? ` This server takes photos up to ${megabytes(state.info.limits.max_image_body)}.` : "";
      say(`The photo could not be sent: ${error.message}.${limit}`, true);
    } else {
      say(error.message, true);
    }
  } finally {
    $("go").disabled = false;
  }
}

function number(value, digits = 3) {
  return value == null ? "–" : Number(value).toPrecision(digits);
}

function degrees(value) {
  return value == null ? "–" : `${Number(value).toFixed(1)}°`;
}

function showAnswer(answer, roundTripMs) {
  const results = answer.results || [];
  $("photo-img").src = answer.photo.src;
  $("photo-img").width = answer.photo.width;
  $("photo-img").height = answer.photo.height;
  const ranking = $("ranking");
  ranking.replaceChildren();
  if (!results.length) say("Nothing in the catalogue matched this photo.", true);
  results.forEach((result, i) => {
    const thumb = el("img", { alt: `${result.object}, matched view`, width: 72, height: 72 });
    showPicture(thumb, result.thumbnail);
    const view = result.view;
    const pose = result.pose;
    const facts = [
      `distance ${number(result.distance)} · score ${number(result.score)}`,
      `colour ${number(result.colour_distance)} · shape fit ${number(result.shape_fit)}`,
      `matched view ${degrees(view.azimuth)}, ${degrees(view.elevation)}${view.mirrored ? " (mirrored)" : ""}`,
      pose ? `pose: azimuth ${degrees(pose.azimuth)}, elevation ${degrees(pose.elevation)}, ` +
             `turn ${degrees(pose.inplane)} (${pose.method}${pose.method === "sift" ? `, ${pose.inliers} inliers` : ""})`
           : `no pose${result.pose_error ? `: ${result.pose_error}` : ""}`,
    ];
    const item = el("li", { "aria-selected": "false", tabindex: "0", "data-object": result.object,
                            onclick: () => select(answer, i), onkeydown: (e) => { if (e.key === "Enter") select(answer, i); } },
      thumb,
      el("div", {},
        el("div", { class: "name" }, el("span", { class: "swatch", style: { background: result.colour } }),
           `${result.rank}. ${result.object}`),
        ...facts.map((text) => el("div", { class: "facts", text }))));
    ranking.append(item);
  });
  showTiming(answer.timing_ms, roundTripMs);
  $("result").hidden = false;
  if (results.length) select(answer, 0);
}

function select(answer, index) {
  const result = answer.results[index];
  const items = $("ranking").children;
  for (let i = 0; i < items.length; i++) items[i].setAttribute("aria-selected", String(i === index));
  const overlay = $("overlay-img");
  state.selected = result;
  if (!result.pose) {
    overlay.hidden = true;
    overlay.removeAttribute("src");
    $("caption").textContent = `${result.rank}. ${result.object}: no pose`;
    return;
  }
  $("caption").textContent = `${result.rank}. ${result.object} drawn in its pose`;
  if (result.overlay) {
    overlay.hidden = false;
    overlay.src = result.overlay;
    return;
  }
  // only the best result's overlay comes with the answer; the server draws the others on request
  overlay.hidden = true;
  $("caption").textContent = `Drawing ${result.object}…`;
  const body = JSON.stringify({ result, width: answer.photo.source_width, height: answer.photo.source_height });
  api("overlay", { method: "POST", body, headers: { "Content-Type": "application/json" } })
    .then((response) => response.blob())
    .then((blob) => {
      result.overlay = URL.createObjectURL(blob);
      if (state.selected === result) select(answer, index);
    })
    .catch((error) => {
      if (!(error instanceof NeedsToken)) $("caption").textContent = `${result.object} could not be drawn: ${error.message}`;
    });
}

const STAGES = [["segment", "segment"], ["client", "client half"], ["server", "server half"],
  ["colour", "colour"], ["verify", "shape fit"], ["pose", "pose"], ["overlay", "overlays"]];

function showTiming(timing, roundTripMs) {
  const rows = STAGES.filter(([key]) => timing[key] != null).map(([key, label]) => [label, timing[key]]);
  rows.push(["server total", (timing.total || 0) + (timing.overlay || 0)]);
  rows.push(["round trip", roundTripMs]);
  const longest = Math.max(...rows.map(([, ms]) => ms), 1);
  $("timing").replaceChildren(...rows.map(([label, ms]) => el("div", { class: "bar" },
    el("span", { text: label }),
    el("span", {}, el("div", { class: "fill", style: { width: `${(100 * ms / longest).toFixed(1)}%` } })),
    el("span", { class: "ms", text: `${Math.round(ms)} ms` }))));
}

// ------------------------------------------------------------------ catalogue
const SYMMETRY = {
  H1: "round about its vertical axis", H2: "one vertical mirror plane", H3: "several vertical mirror planes",
  H4: "no vertical mirror plane", V1: "round about a horizontal axis", V2: "top-bottom mirror",
  V3: "repeats when tipped over", V4: "no top-bottom symmetry",
};

async function loadCatalogue() {
  const message = $("catalogue-message");
  message.textContent = "Loading the catalogue…";
  try {
    const data = await (await api("objects")).json();
    state.catalogueLoaded = true;
    message.textContent = `${data.objects.length} objects on a ${data.gap}° grid. Choose one to turn it.`;
    $("objects").replaceChildren(...data.objects.map((object) => {
      const img = el("img", { alt: object.name, width: 150, height: 150, loading: "lazy" });
      showPicture(img, object.thumbnail);
      const symmetry = object.h_type ? `${object.h_type} · ${object.v_type}` : "symmetry unknown";
      const explained = object.h_type ? `${SYMMETRY[object.h_type] || ""}; ${SYMMETRY[object.v_type] || ""}` : "";
      return el("li", { "data-object": object.name },
        el("button", { type: "button", onclick: () => openTurntable(object) },
          img,
          el("span", { class: "name", text: object.name }),
          el("span", { class: "facts", text: symmetry, title: explained }),
          el("span", { class: "facts", text: `${object.views_stored} of ${object.views_grid} views stored` })));
    }));
  } catch (error) {
    if (error instanceof NeedsToken) state.retry = loadCatalogue;
    else message.textContent = `The catalogue could not be loaded: ${error.message}`;
  }
}

async function openTurntable(object) {
  stopTurntable();
  const dialog = $("turntable");
  $("turntable-title").textContent = object.name;
  $("turntable-symmetry").textContent = object.h_type
    ? `Symmetry ${object.h_type}: ${SYMMETRY[object.h_type] || "?"}; ${object.v_type}: ${SYMMETRY[object.v_type] || "?"}. ` +
      `${object.views_stored} of the ${object.views_grid} grid views stored.`
    : `${object.views_stored} of the ${object.views_grid} grid views stored.`;
  $("turntable-view").textContent = "Loading its views…";
  if (!dialog.open) dialog.showModal();
  try {
    const data = await (await api(`objects/${encodeURIComponent(object.name)}/views`)).json();
    const rings = new Map();
    for (const view of data.views) {
      if (!rings.has(view.elevation)) rings.set(view.elevation, []);
      rings.get(view.elevation).push(view);
    }
    // start on the ring with the most views (a turntable), nearest the horizon on ties
    const order = [...rings.keys()].sort((a, b) => rings.get(b).length - rings.get(a).length ||
      Math.min(a, 360 - a) - Math.min(b, 360 - b));
    const select = $("turntable-ring");
    select.replaceChildren(...[...rings.keys()].sort((a, b) => a - b).map((v) =>
      el("option", { value: String(v), text: `${v}° (${rings.get(v).length})` })));
    select.value = String(order[0]);
    state.turntable = { rings, ring: order[0], step: 0, timer: null, name: object.name, total: data.views.length };
    showRing();
    playTurntable();
  } catch (error) {
    if (error instanceof NeedsToken) dialog.close();
    else $("turntable-view").textContent = `Its views could not be loaded: ${error.message}`;
  }
}

function showRing() {
  const t = state.turntable;
  const views = t.rings.get(t.ring);
  $("turntable-step").max = String(views.length - 1);
  t.step = Math.min(t.step, views.length - 1);
  showStep();
  for (const view of views) picture(view.src).catch(() => {}); // fetch the ring ahead
}

function showStep() {
  const t = state.turntable;
  const view = t.rings.get(t.ring)[t.step];
  $("turntable-step").value = String(t.step);
  $("turntable-view").textContent = `azimuth ${view.azimuth}°, elevation ${view.elevation}°`;
  showPicture($("turntable-img"), view.src);
}

function playTurntable() {
  const t = state.turntable;
  if (!t || t.timer) return;
  $("turntable-play").textContent = "Pause";
  t.timer = setInterval(() => {
    t.step = (t.step + 1) % t.rings.get(t.ring).length;
    showStep();
  }, 600);
}

function stopTurntable() {
  const t = state.turntable;
  if (t && t.timer) { clearInterval(t.timer); t.timer = null; }
  $("turntable-play").textContent = "Play";
}

$("turntable-play").addEventListener("click", () => {
  if (state.turntable && state.turntable.timer) stopTurntable(); else playTurntable();
});
$("turntable-ring").addEventListener("change", (event) => {
  state.turntable.ring = Number(event.target.value);
  showRing();
});
$("turntable-step").addEventListener("input", (event) => {
  stopTurntable();
  state.turntable.step = Number(event.target.value);
  showStep();
});
$("turntable").addEventListener("close", stopTurntable);

start();
