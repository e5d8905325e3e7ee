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
  photo: null, // the chosen file: {file, url, width, height} (its upright pixels; 0 until shown)
  prompts: { boxes: [], points: [] }, // in the photo's pixels
  drag: null, // the box being drawn
  answer: null,
  groups: [], // the answer's objects (one without prompts), each with its ranking and overlay
  asked: null, // what the answer was asked with: {file, fields}, to ask again for another pose
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
// Prompts are drawn on the photo and sent in its own pixels, upright (its EXIF orientation
// applied, as the server reads it): a box means the same pixels as `viewdb query --box`.
const TAP = 8; // CSS pixels: a shorter drag is a tap, a point prompt
const SVG_NS = "http://www.w3.org/2000/svg";
// outline colours of the objects of one answer (the overlays are coloured by rank)
const REGION_COLOURS = ["#00b7ff", "#ff4fa3", "#ffb300", "#8c6bff", "#00c48c", "#ff6d3a"];

function say(text, isError = false) {
  const message = $("message");
  message.hidden = !text;
  message.textContent = text;
  message.className = isError ? "error" : "";
  message.setAttribute("role", isError ? "alert" : "status");
}

function svg(tag, attrs = {}, text = null) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, String(value));
  if (text != null) node.textContent = text;
  return node;
}

function plural(n, one, many) {
  return `${n} ${n === 1 ? one : many}`;
}

function clamp(value, low, high) {
  return Math.min(high, Math.max(low, value));
}

// ------------------------------------------------------------------ the photo and its prompts
$("photo").addEventListener("change", () => choosePhoto($("photo").files[0]));

function choosePhoto(file) {
  if (state.photo) URL.revokeObjectURL(state.photo.url);
  state.photo = null;
  state.prompts = { boxes: [], points: [] };
  clearAnswer();
  say("");
  $("work").hidden = !file;
  if (!file) return;
  const url = URL.createObjectURL(file);
  const photo = { file, url, width: 0, height: 0 };
  state.photo = photo;
  const img = $("photo-img");
  img.removeAttribute("width");
  img.removeAttribute("height");
  // the browser applies the EXIF orientation (image-orientation: from-image), as the server does
  img.onload = () => {
    if (state.photo !== photo) return;
    photo.width = img.naturalWidth;
    photo.height = img.naturalHeight;
    showPrompts();
  };
  img.onerror = () => {
    if (state.photo !== photo) return;
    img.removeAttribute("src");
    showPrompts();
  };
  img.alt = `${file.name || "The photo"}: drag a box around an object or tap it`;
  img.src = url;
  showPrompts();
}

function canDraw() {
  return Boolean(state.photo && state.photo.width);
}

function showPrompts() {
  const photo = state.photo;
  const { boxes, points } = state.prompts;
  const count = boxes.length + points.length;
  $("stage").hidden = !canDraw();
  $("clear-prompts").disabled = !count;
  let hint = "";
  if (photo && !photo.width) {
    hint = "This browser cannot show this photo, so nothing can be drawn on it; Recognise sends it as it is.";
  } else if ($("every").checked) {
    hint = "Every object the photo shows is recognised (objects that touch count as one).";
  } else if (!count) {
    hint = "Drag a box around an object or tap it, several of each, to recognise each one; " +
           "with nothing drawn the photo's one object is recognised.";
  } else {
    const what = [boxes.length ? plural(boxes.length, "box", "boxes") : "",
                  points.length ? plural(points.length, "point", "points") : ""].filter(Boolean).join(" and ");
    hint = `${what}: one object each, numbered as they will be answered.`;
  }
  $("prompt-hint").textContent = hint;
  drawMarks();
}

function addPrompt(kind, values) {
  state.prompts[kind].push(values);
  $("every").checked = false; // prompts or every object, not both
  clearAnswer(); // the answer on show was to other prompts
  showPrompts();
}

$("clear-prompts").addEventListener("click", () => {
  state.prompts = { boxes: [], points: [] };
  clearAnswer();
  showPrompts();
});

$("every").addEventListener("change", () => {
  if ($("every").checked && state.prompts.boxes.length + state.prompts.points.length) {
    state.prompts = { boxes: [], points: [] };
    clearAnswer();
  }
  showPrompts();
});

// a drag draws a box, a tap a point: mouse, pen and touch alike (pointer events)
const marks = $("marks");

function photoPixel(event) {
  const box = marks.getBoundingClientRect();
  const { width, height } = state.photo;
  return [clamp((event.clientX - box.left) / box.width * width, 0, width),
          clamp((event.clientY - box.top) / box.height * height, 0, height)];
}

function spanBox(a, b) {
  return [Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.max(a[0], b[0]), Math.max(a[1], b[1])];
}

marks.addEventListener("pointerdown", (event) => {
  if (!canDraw() || !event.isPrimary || (event.pointerType === "mouse" && event.button !== 0)) return;
  event.preventDefault();
  marks.setPointerCapture(event.pointerId);
  const start = photoPixel(event);
  state.drag = { id: event.pointerId, x: event.clientX, y: event.clientY, start,
                 shape: svg("rect", { class: "drawing", x: start[0], y: start[1], width: 0, height: 0 }) };
  marks.append(state.drag.shape);
});

marks.addEventListener("pointermove", (event) => {
  const drag = state.drag;
  if (!drag || drag.id !== event.pointerId) return;
  const [x1, y1, x2, y2] = spanBox(drag.start, photoPixel(event));
  for (const [key, value] of Object.entries({ x: x1, y: y1, width: x2 - x1, height: y2 - y1 })) {
    drag.shape.setAttribute(key, String(value));
  }
});

marks.addEventListener("pointerup", (event) => {
  const drag = state.drag;
  if (!drag || drag.id !== event.pointerId) return;
  state.drag = null;
  drag.shape.remove();
  const { width, height } = state.photo;
  if (Math.hypot(event.clientX - drag.x, event.clientY - drag.y) < TAP) {
    // the pixel tapped
    addPrompt("points", [clamp(Math.floor(drag.start[0]), 0, width - 1), clamp(Math.floor(drag.start[1]), 0, height - 1)]);
  } else {
    addPrompt("boxes", spanBox(drag.start, photoPixel(event)).map(Math.round));
  }
});

marks.addEventListener("pointercancel", () => {
  if (state.drag) state.drag.shape.remove();
  state.drag = null;
});

function drawMarks() {
  marks.replaceChildren();
  if (!canDraw()) return;
  const { width, height } = state.photo;
  marks.setAttribute("viewBox", `0 0 ${width} ${height}`);
  const side = Math.max(width, height);
  const font = side / 26;
  const label = (text, x, y, attrs = {}) => svg("text", {
    x: clamp(x, 0, width - font), y: clamp(y, font, height), "font-size": font, ...attrs }, text);
  const { boxes, points } = state.prompts;
  boxes.forEach(([x1, y1, x2, y2], i) => {
    marks.append(svg("rect", { class: "prompt", x: x1, y: y1, width: x2 - x1, height: y2 - y1 }),
                 label(String(i + 1), x1 + font * 0.25, y1 + font, { class: "prompt-label" }));
  });
  const radius = side / 80;
  points.forEach(([x, y], j) => {
    marks.append(svg("circle", { class: "prompt", cx: x + 0.5, cy: y + 0.5, r: radius }),
                 svg("circle", { class: "prompt-dot", cx: x + 0.5, cy: y + 0.5, r: radius / 4 }),
                 label(String(boxes.length + j + 1), x + radius * 1.4, y - radius * 0.6, { class: "prompt-label" }));
  });
  // an answer's objects: each cut-out's bounding box
  (state.groups || []).forEach((group) => {
    if (!group.region) return;
    const [x1, y1, x2, y2] = group.region.box;
    marks.append(svg("rect", { class: "region", x: x1, y: y1, width: x2 - x1, height: y2 - y1,
                               stroke: group.colour, "data-object": group.index }),
                 label(String(group.index + 1), x1 + font * 0.25, y2 - font * 0.25,
                       { class: "region-label", fill: group.colour }));
  });
}

// ------------------------------------------------------------------ recognise
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
  const { boxes, points } = state.prompts;
  const every = $("every").checked;
  const fields = { plan: $("plan").value, k: $("k").value, boxes: [...boxes], points: [...points], every,
                   intrinsics: $("intrinsics").value.trim(), depth: $("depth").files[0] || null,
                   depthScale: $("depth-scale").value.trim() };
  const form = queryForm(file, fields);
  if (!state.photo || state.photo.file !== file) choosePhoto(file);
  const photo = state.photo;
  const sent = { prompts: boxes.length + points.length, width: photo ? photo.width : 0, height: photo ? photo.height : 0 };
  $("go").disabled = true;
  clearAnswer();
  const what = every ? "every object" : sent.prompts ? plural(sent.prompts, "object", "objects") : "the object";
  say(`Recognising ${what} in ${file.name || "the photo"} (${megabytes(file.size)})…`);
  const started = performance.now();
  try {
    const response = await api("query", { method: "POST", body: form });
    const answer = await response.json();
    if (state.photo !== photo) return; // another photo was chosen meanwhile
    say("");
    state.asked = { file, fields };
    showAnswer(answer, performance.now() - started, sent);
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

// the form of POST /query; pose_top as the library's default unless given
function queryForm(file, fields, poseTop = null) {
  const form = new FormData();
  form.append("photo", file, file.name || "photo.jpg");
  form.append("plan", fields.plan);
  if (fields.k) form.append("k", fields.k);
  if (poseTop != null) form.append("pose_top", String(poseTop));
  for (const box of fields.boxes) form.append("box", box.join(","));
  for (const point of fields.points) form.append("point", point.join(","));
  if (fields.every) form.append("all", "true");
  if (fields.intrinsics) form.append("intrinsics", fields.intrinsics);
  if (fields.depth) form.append("depth", fields.depth, fields.depth.name || "depth.png");
  if (fields.depth && fields.depthScale) form.append("depth_scale", fields.depthScale);
  return form;
}

function number(value, digits = 3) {
  return value == null ? "–" : Number(value).toPrecision(digits);
}

function degrees(value) {
  return value == null ? "–" : `${Number(value).toFixed(1)}°`;
}

function caption(text) {
  $("caption").hidden = !text;
  $("caption").textContent = text;
}

function clearAnswer() {
  state.answer = null;
  state.groups = [];
  $("layers").replaceChildren();
  $("answers").replaceChildren();
  $("answers").hidden = true;
  $("time-block").hidden = true;
  caption("");
  drawMarks();
}

// ------------------------------------------------------------------ the answer
function showAnswer(answer, roundTripMs, sent) {
  const photo = answer.photo;
  const img = $("photo-img");
  img.onload = img.onerror = null;
  img.src = photo.src; // the photo as the server read it: the overlays are drawn on it
  img.width = photo.width;
  img.height = photo.height;
  img.alt = `${answer.image} as the server read it`;
  if (sent.prompts && (sent.width !== photo.source_width || sent.height !== photo.source_height)) {
    // this browser turned the photo otherwise than its EXIF orientation says
    say(`This browser showed the photo at ${sent.width}×${sent.height} pixels but it is ` +
        `${photo.source_width}×${photo.source_height} upright, so the boxes and points missed their objects; ` +
        "draw them again on the photo as it is shown now.", true);
    state.prompts = { boxes: [], points: [] };
  }
  state.photo.width = photo.source_width;
  state.photo.height = photo.source_height;
  state.answer = answer;
  const several = Boolean(answer.objects);
  state.groups = several
    ? answer.objects.map((entry, i) => ({ index: i, region: entry.region, segmentation: entry.segmentation,
                                          results: entry.results, colour: REGION_COLOURS[i % REGION_COLOURS.length] }))
    : [{ index: 0, region: null, results: answer.results || [], colour: null }];
  if (!state.groups.some((group) => group.results.length)) say("Nothing in the catalogue matched this photo.", true);
  $("answers").replaceChildren(...state.groups.map((group) => objectSection(group, several)));
  $("layers").replaceChildren(...state.groups.map((group) => {
    group.layer = el("img", { class: "layer", alt: several ? `Object ${group.index + 1}'s result drawn in its pose`
                                                           : "The selected result's mesh drawn in its pose" });
    group.layer.hidden = true;
    return group.layer;
  }));
  showTiming(answer.timing_ms, roundTripMs);
  $("answers").hidden = false;
  $("time-block").hidden = false;
  showPrompts();
  for (const group of state.groups) if (group.results.length) select(group, 0, !several);
  if (several) caption(`${plural(state.groups.length, "object", "objects")}, each with its best result in its pose`);
}

// the query poses its best result, as the library does; another is posed when it is
// chosen, by asking again with pose_top reaching it (posing does not reorder the ranking)
function poseOnRequest(group, index, announce) {
  const answer = state.answer;
  const result = group.results[index];
  const tell = (text) => { if (announce) caption(text); };
  group.layer.hidden = true;
  tell(`Posing ${result.rank}. ${result.object}…`);
  if (result.posing) return;
  result.posing = true;
  const { file, fields } = state.asked;
  api("query", { method: "POST", body: queryForm(file, fields, result.rank) })
    .then((response) => response.json())
    .then((again) => {
      const entries = group.region ? ((again.objects || [])[group.index] || {}).results : again.results;
      const posed = (entries || [])[index];
      const same = posed && posed.object === result.object && posed.view.azimuth === result.view.azimuth
        && posed.view.elevation === result.view.elevation;
      result.pose = same ? posed.pose : null;
      result.pose_error = !same ? "asked again, the query answered otherwise"
        : posed.pose ? null : posed.pose_error || "the query did not pose it";
      result.overlay = same ? posed.overlay : null;
      const item = resultItem(group, result, index);
      item.setAttribute("aria-selected", String(group.selected === result));
      group.list.children[index].replaceWith(item);
      if (state.answer === answer && group.selected === result) select(group, index, announce);
    })
    .catch((error) => {
      if (!(error instanceof NeedsToken)) tell(`${result.object} could not be posed: ${error.message}`);
    })
    .finally(() => { result.posing = false; });
}

function regionText(group) {
  const prompt = group.region.prompt;
  const from = !prompt ? "found on its own"
    : prompt.box ? `from the box ${prompt.box.map((v) => Math.round(v)).join(", ")}`
    : `from the point ${prompt.point.map((v) => Math.round(v)).join(", ")}`;
  return `${from} · cut out ${group.region.area.toLocaleString("en")} pixels within ${group.region.box.join(", ")}`;
}

function objectSection(group, several) {
  group.list = el("ol", { class: "ranking" }, ...group.results.map((result, i) => resultItem(group, result, i)));
  if (!several) return el("section", { class: "found" }, group.list);
  return el("section", { class: "found several", "data-index": String(group.index) },
    el("h3", {}, el("span", { class: "tag", style: { background: group.colour }, text: String(group.index + 1) }),
       `Object ${group.index + 1}`),
    el("p", { class: "facts", text: regionText(group) }),
    group.results.length ? group.list : el("p", { class: "muted", text: "Nothing in the catalogue matched this object." }));
}

function resultItem(group, result, i) {
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
         : result.pose_error ? `no pose: ${result.pose_error}` : "not posed yet: choose it to pose it",
  ];
  return el("li", { "aria-selected": "false", tabindex: "0", "data-object": result.object,
                    onclick: () => select(group, i), onkeydown: (e) => { if (e.key === "Enter") select(group, i); } },
    thumb,
    el("div", {},
      el("div", { class: "name" }, el("span", { class: "swatch", style: { background: result.colour } }),
         `${result.rank}. ${result.object}`),
      ...facts.map((text) => el("div", { class: "facts", text }))));
}

function select(group, index, announce = true) {
  const answer = state.answer;
  const result = group.results[index];
  const items = group.list.children;
  for (let i = 0; i < items.length; i++) items[i].setAttribute("aria-selected", String(i === index));
  const layer = group.layer;
  const who = `${group.region ? `Object ${group.index + 1}: ` : ""}${result.rank}. ${result.object}`;
  const tell = (text) => { if (announce) caption(text); };
  group.selected = result;
  if (!result.pose && !result.pose_error && state.asked) {
    poseOnRequest(group, index, announce);
    return;
  }
  if (!result.pose) {
    layer.hidden = true;
    layer.removeAttribute("src");
    tell(`${who}: no pose`);
    return;
  }
  if (result.overlay) {
    layer.hidden = false;
    layer.src = result.overlay;
    tell(`${who} drawn in its pose`);
    return;
  }
  // only each object's best posed result comes with its overlay; the server draws the others on request
  layer.hidden = true;
  tell(`Drawing ${result.object}…`);
  const body = JSON.stringify({ result, width: answer.photo.source_width, height: answer.photo.source_height,
                                intrinsics: answer.intrinsics || null });
  api("overlay", { method: "POST", body, headers: { "Content-Type": "application/json" } })
    .then((response) => response.blob())
    .then((blob) => {
      result.overlay = URL.createObjectURL(blob);
      if (state.answer === answer && group.selected === result) select(group, index, announce);
    })
    .catch((error) => {
      if (!(error instanceof NeedsToken)) caption(`${result.object} could not be drawn: ${error.message}`);
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
