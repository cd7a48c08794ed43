// The camera image with the markers detected on it, and the operator prompts of
// `ask_operator` (confirm, choose, click on an image: the click goes back as the image's
// pixel coordinates [u, v], (0, 0) top left).

import {api, imageUrl} from "./api.js";
import {el, fmtTime} from "./util.js";

function drawShape(ctx, shape, sx, sy) {
  const pts = shape.points.map(([u, v]) => [u * sx, v * sy]);
  ctx.strokeStyle = shape.color || "#ffeb3b";
  ctx.fillStyle = shape.color || "#ffeb3b";
  ctx.lineWidth = 2;
  ctx.beginPath();
  if (shape.shape === "box" && pts.length === 2) {
    ctx.rect(pts[0][0], pts[0][1], pts[1][0] - pts[0][0], pts[1][1] - pts[0][1]);
  } else if (shape.shape === "point" || shape.shape === "text") {
    ctx.arc(pts[0][0], pts[0][1], 4, 0, 2 * Math.PI);
  } else {
    pts.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    if (shape.shape === "polygon") ctx.closePath();
  }
  ctx.stroke();
  if (shape.label) {
    ctx.font = "bold 12px sans-serif";
    const [x, y] = pts[0];
    ctx.lineWidth = 3;
    ctx.strokeStyle = "rgba(0, 0, 0, 0.7)";
    ctx.strokeText(shape.label, x + 3, y - 4);
    ctx.fillText(shape.label, x + 3, y - 4);
  }
}

export class CameraView {
  constructor(canvas, info) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.info = info;
    this.frame = null;        // {t, width, height, img, detections}
    this.placeholder();
  }

  placeholder() {
    const ctx = this.ctx;
    ctx.fillStyle = "#22252b";
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    ctx.fillStyle = "#9aa0a6";
    ctx.font = "13px sans-serif";
    ctx.fillText("no camera frame yet (frames come while a skill uses the camera)", 12, 22);
  }

  reset() {
    this.frame = null;
    this.canvas.width = 520;
    this.canvas.height = 390;
    this.info.textContent = "";
    this.placeholder();
  }

  setFrame(msg) {
    const img = new Image();
    img.onload = () => {
      this.frame = {t: msg.t, width: msg.width, height: msg.height, img, detections: msg.detections || []};
      this.draw();
    };
    img.src = `data:image/jpeg;base64,${msg.jpeg}`;
  }

  draw() {
    const f = this.frame;
    if (!f) return;
    const c = this.canvas;
    if (c.width !== f.width || c.height !== f.height) {
      c.width = f.width;
      c.height = f.height;
    }
    this.ctx.drawImage(f.img, 0, 0);
    const shown = f.detections;  // the markers found on this very frame
    for (const det of shown) drawShape(this.ctx, {shape: "polygon", points: det.points, label: det.label,
                                                   color: "#00e676"}, 1, 1);
    this.info.textContent = `${f.width}×${f.height}, t ${fmtTime(f.t)}, ${shown.length} detection${shown.length === 1 ? "" : "s"}`;
  }
}

export class PromptView {
  constructor(card, box) {
    this.card = card;
    this.box = box;
    this.prompts = new Map();  // id -> {prompt, node, error}
    this.clock = 0;
  }

  // All open prompts (hello, reconnect).
  reset(prompts) {
    for (const entry of this.prompts.values()) entry.node.remove();
    this.prompts.clear();
    for (const p of prompts || []) this.add(p);
    this.refresh();
  }

  // A `prompt` stream message: {action: prompt | prompt_answered | prompt_closed, ...}.
  message(data) {
    if (data.action === "prompt") this.add(data);
    else this.remove(data.id);
    this.refresh();
  }

  tick(t) {
    this.clock = t;
    for (const entry of this.prompts.values()) this.countdown(entry);
  }

  countdown(entry) {
    const p = entry.prompt;
    if (p.timeout == null) return;
    const left = Math.max(0, p.asked_at + p.timeout - this.clock);
    entry.timer.textContent = `${left.toFixed(0)} s left`;
  }

  refresh() {
    this.card.hidden = this.prompts.size === 0;
  }

  remove(id) {
    const entry = this.prompts.get(id);
    if (!entry) return;
    entry.node.remove();
    this.prompts.delete(id);
  }

  add(p) {
    if (this.prompts.has(p.id)) return;
    const error = el("p", {class: "error", role: "alert", hidden: true});
    const timer = el("span", {class: "muted"});
    const controls = el("div", {class: "answers"});
    const node = el("div", {class: `prompt kind-${p.kind}`, "data-prompt": p.id},
      el("p", {class: "question"}, p.text),
      el("p", {class: "muted small"}, `${p.kind} · ${p.node || ""} · `, timer),
      controls, error);
    const entry = {prompt: p, node, error, timer};
    this.prompts.set(p.id, entry);
    this.box.append(node);
    this.countdown(entry);
    const answer = async (value) => {
      const r = await api("POST", `/api/prompts/${encodeURIComponent(p.id)}/answer`, {answer: value, source: "console"});
      if (r.ok) {
        this.remove(p.id);
        this.refresh();
      } else {
        error.hidden = false;
        error.textContent = r.data && r.data.error ? r.data.error : `error ${r.status}`;
      }
    };
    if (p.kind === "confirm") {
      controls.append(
        button("Yes", "yes", () => answer(true)),
        button("No", "no", () => answer(false)));
    } else if (p.kind === "choose") {
      for (const opt of p.options) controls.append(button(opt, "option", () => answer(opt)));
    }
    if (p.image_url) this.showImage(p, controls, answer, error);
  }

  async showImage(p, controls, answer, error) {
    const [w, h] = p.image_size || [0, 0];
    const canvas = el("canvas", {class: p.kind === "point" ? "clickable" : "", width: w, height: h,
                                 title: p.kind === "point" ? "click to answer" : ""});
    const hint = el("p", {class: "muted small"}, p.kind === "point" ? `click on the image (${w}×${h} pixels)` : "");
    controls.append(canvas, hint);
    let url;
    try {
      url = await imageUrl(p.image_url);
    } catch (e) {
      error.hidden = false;
      error.textContent = `the prompt's image could not be loaded: ${e.message}`;
      return;
    }
    const img = new Image();
    img.onload = () => {
      const ctx = canvas.getContext("2d");
      canvas.width = img.naturalWidth;
      canvas.height = img.naturalHeight;
      ctx.drawImage(img, 0, 0);
      for (const shape of p.overlay || []) drawShape(ctx, shape, 1, 1);
      URL.revokeObjectURL(url);
    };
    img.src = url;
    if (p.kind !== "point") return;
    canvas.addEventListener("click", (ev) => {
      const r = canvas.getBoundingClientRect();
      const u = Math.min(canvas.width - 1, Math.max(0, Math.floor((ev.clientX - r.left) * canvas.width / r.width)));
      const v = Math.min(canvas.height - 1, Math.max(0, Math.floor((ev.clientY - r.top) * canvas.height / r.height)));
      const ctx = canvas.getContext("2d");
      drawShape(ctx, {shape: "point", points: [[u, v]], label: `${u}, ${v}`, color: "#ff1744"}, 1, 1);
      answer([u, v]);
    });
  }
}

function button(text, cls, onClick) {
  const b = el("button", {type: "button", class: cls}, text);
  b.addEventListener("click", onClick);
  return b;
}
