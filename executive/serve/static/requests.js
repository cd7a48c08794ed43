// The request form (built from the mission's request fields) and the request list: the
// running request and the queue with their cancel buttons, then the finished ones.

import {api} from "./api.js";
import {el} from "./util.js";

const HINT = {int: "a whole number", float: "a number", str: "text", bool: "true or false",
              list: "a YAML list, e.g. [1, 2]", dict: "a YAML mapping, e.g. {a: 1}"};

export class RequestForm {
  constructor(form, fields, error, doc, onSubmitted) {
    this.form = form;
    this.fieldsBox = fields;
    this.error = error;
    this.doc = doc;
    this.onSubmitted = onSubmitted;
    this.inputs = new Map();  // field name -> input
    this.shape = "";
    form.addEventListener("submit", (ev) => {
      ev.preventDefault();
      this.submit();
    });
  }

  setMission(mission) {
    this.doc.textContent = mission.description || "";
    const shape = JSON.stringify(mission.requests);
    if (shape === this.shape) return;
    this.shape = shape;
    this.inputs.clear();
    const rows = mission.requests.map((f) => {
      let input;
      // a field with a default may be left empty (the service then uses the default)
      const dflt = "default" in f ? `default: ${JSON.stringify(f.default)}` : null;
      if (f.type === "bool") {
        input = el("select", {id: `field-${f.name}`, name: f.name},
          dflt ? el("option", {value: ""}, dflt) : "",
          el("option", {value: "true"}, "true"), el("option", {value: "false"}, "false"));
      } else {
        input = el("input", {id: `field-${f.name}`, name: f.name, type: "text", autocomplete: "off",
                             spellcheck: "false", inputmode: f.type === "int" || f.type === "float" ? "decimal" : null,
                             placeholder: dflt ? `${HINT[f.type] || f.type} (${dflt})` : HINT[f.type] || f.type});
      }
      this.inputs.set(f.name, input);
      return el("div", {class: "field"},
        el("label", {for: `field-${f.name}`}, f.name, " ", el("span", {class: "type"}, f.type)),
        input,
        f.doc ? el("small", {class: "muted"}, f.doc) : "");
    });
    if (rows.length === 0) rows.push(el("p", {class: "muted"}, "This mission's requests have no fields."));
    this.fieldsBox.replaceChildren(...rows);
    this.showError("");
  }

  // The fields as typed: the service converts strings to the declared types and says
  // exactly what is wrong (the message --request prints); an empty field is left out.
  values() {
    const out = {};
    for (const [name, input] of this.inputs) {
      const v = input.value.trim();
      if (v !== "") out[name] = input.tagName === "SELECT" ? v === "true" : v;
    }
    return out;
  }

  async submit() {
    const r = await api("POST", "/api/requests", this.values());
    if (r.ok) {
      this.showError("");
      this.onSubmitted(r.data);
      return;
    }
    this.showError(r.data && r.data.error ? r.data.error : `error ${r.status}`);
  }

  // Show the service's message and mark the field it names.
  showError(message) {
    this.error.hidden = !message;
    this.error.textContent = message;
    const m = /field '([^']+)'/.exec(message);
    for (const [name, input] of this.inputs) {
      const bad = !!message && (!m || m[1] === name);
      input.classList.toggle("invalid", bad);
      input.setAttribute("aria-invalid", bad ? "true" : "false");
    }
    if (m && this.inputs.has(m[1])) this.inputs.get(m[1]).focus();
  }
}

function describe(req) {
  return Object.entries(req.request).map(([k, v]) => `${k}=${v}`).join(", ") || "(no fields)";
}

export class RequestList {
  constructor(queueBox, finishedBox, onChanged) {
    this.queueBox = queueBox;
    this.finishedBox = finishedBox;
    this.onChanged = onChanged;
  }

  async cancel(req, button) {
    button.disabled = true;
    const r = await api("DELETE", `/api/requests/${req.id}`);
    if (!r.ok) {
      button.disabled = false;
      button.title = r.data && r.data.error ? r.data.error : "";
    }
    this.onChanged();
  }

  item(req, cancellable) {
    const state = el("span", {class: `pill state-${req.state}`}, req.state);
    const li = el("li", {"data-request": req.id, "data-state": req.state},
      el("span", {class: "rid"}, `#${req.id}`), el("span", {class: "what"}, describe(req)), state,
      req.duration != null ? el("span", {class: "muted"}, `${req.duration.toFixed(1)} s`) : "");
    if (cancellable) {
      const b = el("button", {type: "button", class: "cancel small", title: req.state === "running" ?
        "halt this request (the robot stops safely; the queue goes on)" : "drop it from the queue"},
        req.state === "running" ? "Halt" : "Cancel");
      b.addEventListener("click", () => this.cancel(req, b));
      li.append(b);
    }
    if (req.reason) li.append(el("div", {class: req.state === "success" ? "reason" : "reason bad"}, req.reason));
    return li;
  }

  update(data) {
    const running = data.current ? [this.item(data.current, data.current.reason !== "halting")] : [];
    const queued = data.queued.map((r) => this.item(r, true));
    this.queueBox.replaceChildren(...running, ...queued);
    if (running.length + queued.length === 0) this.queueBox.append(el("li", {class: "muted"}, "nothing queued"));
    this.finishedBox.replaceChildren(...data.finished.slice(0, 20).map((r) => this.item(r, false)));
    if (data.finished.length === 0) this.finishedBox.append(el("li", {class: "muted"}, "none yet"));
  }
}
