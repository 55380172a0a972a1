// The try-on page: pick garments, their order and sizes, set the body (girths optional), POST /v1/outfits,
// show the GLB and the body's measurements.
const $ = (id) => document.getElementById(id);

// model-viewer decodes EXT_meshopt_compression once it is given a meshopt decoder's location (it loads
// that script, then uses its bundled copy): the vendored official decoder, so no CDN is needed.
const MESHOPT_DECODER = "/static/vendor/meshopt_decoder.js";
customElements.whenDefined("model-viewer").then(() => {
  customElements.get("model-viewer").meshoptDecoderLocation = MESHOPT_DECODER;
  mark("viewerDefined");
});

// Shown at first, so the view is never empty: the first of these present in the catalog.
const DEFAULT_OUTFIT = ["pants", "tshirt"];

// The girth inputs and the request fields they fill; an empty one is left out (predicted).
const GIRTHS = [["chest", "chest_cm", "chest"], ["waist", "waist_cm", "waist"], ["hip", "hip_cm", "hip"]];

const layers = []; // garment ids, inner to outer
const sizes = {}; // garment id -> the size picked ("" or absent: one size, cut to the body)
let catalog = [];
let rangesAsked = 0; // the latest /v1/body/ranges request: older answers are dropped

// Milliseconds since navigation of each step, for the page test (tests/js/page.mjs).
window.pageTimings = {};
function mark(name) {
  window.pageTimings[name] = Math.round(performance.now());
}
mark("script");

function renderLayers() {
  const list = $("layers");
  list.replaceChildren(...layers.map((id, i) => {
    const item = document.createElement("li");
    const garment = catalog.find((g) => g.id === id);
    item.textContent = garment.name;
    if ((garment.sizes || []).length) item.append(sizePicker(garment));
    for (const [label, step, title] of [["↑", -1, "inner"], ["↓", 1, "outer"]]) {
      const button = document.createElement("button");
      button.type = "button";
      button.textContent = label;
      button.title = `move ${title}`;
      button.disabled = i + step < 0 || i + step >= layers.length;
      button.onclick = () => {
        [layers[i], layers[i + step]] = [layers[i + step], layers[i]];
        renderLayers();
      };
      item.append(button);
    }
    return item;
  }));
}

// A garment's size picker: "one size" (cut to the body, as a bare id) or one of the sizes it comes in.
function sizePicker(garment) {
  const select = document.createElement("select");
  select.name = `size-${garment.id}`;
  select.title = `size of the ${garment.name}`;
  select.append(new Option("one size", ""), ...garment.sizes.map((s) => new Option(s, s)));
  select.value = sizes[garment.id] || "";
  select.onchange = () => { sizes[garment.id] = select.value; };
  return select;
}

// The request's garments: an id, or {id, size} where a size is picked.
function requestGarments() {
  return layers.map((id) => (sizes[id] ? { id, size: sizes[id] } : id));
}

function toggle(id, on) {
  const at = layers.indexOf(id);
  if (on && at < 0) {
    // Default order: by category rank, so a new top goes over the tops already chosen.
    const rank = (g) => catalog.find((c) => c.id === g).layer_rank;
    const pos = layers.findIndex((g) => rank(g) > rank(id));
    layers.splice(pos < 0 ? layers.length : pos, 0, id);
  } else if (!on && at >= 0) {
    layers.splice(at, 1);
  }
  renderLayers();
}

function showValues() {
  $("gender-value").textContent = Number($("gender").value).toFixed(2);
  $("height-value").textContent = $("height").value;
  $("weight-value").textContent = $("weight").value;
}

function setRange(slider, range) {
  // Whole numbers inside the accepted range (the slider's step is 1), the value moved into it.
  slider.min = Math.ceil(range.min);
  slider.max = Math.floor(range.max);
  slider.value = Math.min(Math.max(Number(slider.value), slider.min), slider.max);
}

// The sliders offer only what the service accepts: heights, weights at the height, and the girth inputs
// the girths possible for the gender at that height and weight (a value outside them is still sent, and
// the service's refusal shown).
async function followRanges() {
  const asked = ++rangesAsked;
  const query = new URLSearchParams({ gender: $("gender").value, height_cm: $("height").value,
                                      weight_kg: $("weight").value });
  const response = await fetch(`/v1/body/ranges?${query}`);
  if (!response.ok || asked !== rangesAsked) return;
  const ranges = await response.json();
  setRange($("height"), ranges.height_cm);
  // A height moved into its range (rounded to the slider's whole cm): the weights at that height.
  if (ranges.weight_at_height_cm !== Number($("height").value)) return followRanges();
  setRange($("weight"), ranges.weight_kg);
  if (ranges.girths_at_weight_kg !== Number($("weight").value)) return followRanges();
  for (const [id, field] of GIRTHS) {
    const { min, max } = ranges[field];
    Object.assign($(id), { min, max, title: `${min}-${max} cm at this gender, height and weight` });
  }
  showValues();
  document.body.dataset.ranges = `${$("gender").value} ${$("height").min}-${$("height").max} ` +
                                 `${$("weight").min}-${$("weight").max} ` +
                                 GIRTHS.map(([id]) => `${$(id).min}-${$(id).max}`).join(" ");
}

// The girths filled in, as request fields; throws naming an input that holds no number.
function girths() {
  const given = {};
  for (const [id, field, name] of GIRTHS) {
    if ($(id).validity.badInput) throw new Error(`${name}: not a number (leave it empty to predict it)`);
    if ($(id).value !== "") given[field] = Number($(id).value);
  }
  return given;
}

// The body as built (report.body): its measurements, the predicted ones marked and shown as the empty
// inputs' placeholders.
function showBody(body) {
  const predicted = new Set(body.predicted);
  const parts = GIRTHS.map(([id, field, name]) => {
    $(id).placeholder = predicted.has(field) ? `${body[field].toFixed(1)}` : "";
    return `${name} ${body[field].toFixed(1)}${predicted.has(field) ? "*" : ""}`;
  });
  $("measured").textContent = `Body: ${parts.join(", ")} cm` + (predicted.size ? " (* predicted)" : "");
  document.body.dataset.measured = JSON.stringify(body);
}

const statusLog = (window.statusLog = []); // every status shown, for the page test
function status(text, state = "") {
  $("status").textContent = text;
  $("status").className = state; // "error", "busy" (a spinner) or ""
  statusLog.push([state, text]);
}

function clearView() {
  $("viewer").removeAttribute("src");
  $("measured").textContent = "";
  delete document.body.dataset.shown;
  delete document.body.dataset.measured;
}

function showGlb(url) {
  const viewer = $("viewer");
  return new Promise((resolve) => {
    const done = (event) => {
      viewer.removeEventListener("load", done);
      viewer.removeEventListener("error", done);
      viewer.removeEventListener("progress", progress);
      resolve(event.type);
    };
    const progress = (event) => {
      const share = Math.round(100 * (event.detail?.totalProgress || 0));
      if (share < 100) status(`Loading the 3D view… ${share}%`, "busy");
    };
    viewer.addEventListener("load", done);
    viewer.addEventListener("error", done);
    viewer.addEventListener("progress", progress);
    viewer.src = url;
  });
}

// The report's strain per garment, when the tension map was asked for.
function tensionText(report) {
  const tension = report.tension;
  if (!tension) return "";
  const rows = Object.entries(tension).map(([id, t]) =>
    `${id} ${report.sizes?.[id] || "one size"}: ${Math.round(100 * t.stretched_share)} % of it stretched ` +
    `over 2 %, median ${(100 * t.stretch_p50).toFixed(1)} %`);
  return `\n${rows.join("\n")}`;
}

async function dress() {
  if (!layers.length) {
    clearView();
    return status("Pick at least one garment.", "error");
  }
  let given;
  try {
    given = girths();
  } catch (err) {
    clearView();
    return status(err.message, "error");
  }
  const request = {
    garments: requestGarments(),
    body: { gender: Number($("gender").value), height_cm: Number($("height").value),
            weight_kg: Number($("weight").value), ...given },
    // The tension map is written in the plain encoding only.
    options: { untangle: $("untangle").checked, include_body: $("include-body").checked,
               compression: $("tension").checked ? "none" : $("compression").value,
               tension: $("tension").checked },
  };
  const names = layers.map((id) => (sizes[id] ? `${id} ${sizes[id]}` : id)).join(" < ");
  $("dress").disabled = true;
  status(`Dressing ${names}…`, "busy");
  mark("dress");
  const t0 = performance.now();
  try {
    const response = await fetch("/v1/outfits", {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(request),
    });
    const answer = await response.json();
    if (!response.ok) {
      clearView(); // never the previous outfit under a refusal
      const messages = (answer.errors || []).map((e) => e.message).join("\n");
      return status(messages || answer.detail || `HTTP ${response.status}`, "error");
    }
    mark("answered");
    if (answer.report.body) showBody(answer.report.body);
    const made = Math.round(performance.now() - t0);
    status("Loading the 3D view…", "busy");
    const event = await showGlb(answer.glb_url);
    mark("shown");
    if (event !== "load") {
      clearView();
      return status("The 3D view could not show the outfit.", "error");
    }
    document.body.dataset.shown = answer.glb_url;
    const shown = Math.round(performance.now() - t0);
    const fallback = answer.report.numerical_fallback || [];
    status(`${names}: made in ${made} ms${answer.cached ? " (cached)" : ""}, on screen in ${shown} ms` +
           (fallback.length ? `\nnot fitted: ${fallback.join(", ")}` : "") + tensionText(answer.report));
  } catch (err) {
    clearView();
    status(`Request failed: ${err}`, "error");
  } finally {
    $("dress").disabled = false;
  }
}

async function main() {
  for (const id of ["gender", "height", "weight"]) $(id).addEventListener("input", showValues);
  for (const id of ["gender", "height", "weight"]) $(id).addEventListener("change", followRanges);
  showValues();
  $("dress").onclick = dress;
  const response = await fetch("/v1/garments");
  if (!response.ok) return status("Could not load the catalog.", "error");
  catalog = (await response.json()).garments;
  mark("catalog");
  $("catalog").replaceChildren(...catalog.map((g) => {
    const label = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.value = g.id;
    box.name = "garment";
    box.onchange = () => toggle(g.id, box.checked);
    label.append(box, ` ${g.name}`);
    return label;
  }));
  await followRanges();
  document.body.dataset.ready = "true";
  const preset = DEFAULT_OUTFIT.filter((id) => catalog.some((g) => g.id === id));
  for (const id of preset.length ? preset : catalog.slice(0, 1).map((g) => g.id)) {
    document.querySelector(`input[name=garment][value=${id}]`).checked = true;
    toggle(id, true);
  }
  await dress();
  document.body.dataset.first = "done";
}

main();
