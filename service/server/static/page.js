// The try-on page: pick garments and their order, set the body, POST /v1/outfits, show the GLB.
const $ = (id) => document.getElementById(id);

// model-viewer decodes EXT_meshopt_compression once it is given a meshopt decoder's location (it loads
// that script, then uses its bundled copy): the vendored official decoder, so no CDN is needed.
const MESHOPT_DECODER = "/static/vendor/meshopt_decoder.js";
customElements.whenDefined("model-viewer").then(() => {
  customElements.get("model-viewer").meshoptDecoderLocation = MESHOPT_DECODER;
});

const layers = []; // garment ids, inner to outer
let catalog = [];

function renderLayers() {
  const list = $("layers");
  list.replaceChildren(...layers.map((id, i) => {
    const item = document.createElement("li");
    item.textContent = catalog.find((g) => g.id === id).name;
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

function status(text, error = false) {
  $("status").textContent = text;
  $("status").className = error ? "error" : "";
}

async function dress() {
  if (!layers.length) return status("Pick at least one garment.", true);
  const request = {
    garments: layers,
    body: { gender: Number($("gender").value), height_cm: Number($("height").value),
            weight_kg: Number($("weight").value) },
    options: { untangle: $("untangle").checked, include_body: $("include-body").checked,
               compression: $("compression").value },
  };
  $("dress").disabled = true;
  status("Dressing…");
  const t0 = performance.now();
  try {
    const response = await fetch("/v1/outfits", {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(request),
    });
    const answer = await response.json();
    if (!response.ok) return status(answer.detail || `HTTP ${response.status}`, true);
    const ms = Math.round(performance.now() - t0);
    const fallback = answer.report.numerical_fallback || [];
    status(`${layers.join(" < ")}: ${ms} ms${answer.cached ? " (cached)" : ""}` +
           (fallback.length ? `\nnot fitted: ${fallback.join(", ")}` : ""));
    $("viewer").src = answer.glb_url;
  } catch (err) {
    status(`Request failed: ${err}`, true);
  } finally {
    $("dress").disabled = false;
  }
}

async function main() {
  for (const id of ["gender", "height", "weight"]) $(id).addEventListener("input", showValues);
  showValues();
  $("dress").onclick = dress;
  const response = await fetch("/v1/garments");
  if (!response.ok) return status("Could not load the catalog.", true);
  catalog = (await response.json()).garments;
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
  document.body.dataset.ready = "true";
}

main();
