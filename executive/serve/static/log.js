// The event log's tail: every record as the service writes it, filterable by text, with
// failures (a skill or request that failed, a recovery, a halt, a dropped request, a
// timed-out prompt, a warning) highlighted and their reason shown.

import {el, fmtValue} from "./util.js";

const KEEP = 2000;   // records kept in the page
const SHOW = 400;    // rows shown at most (the newest that match)
const QUIET = new Set(["event", "seq", "t", "node", "nodes", "versions"]);
const RENDER_EVERY = 200;  // [ms]

// Why a record is a failure ("" when it is not one).
export function failureOf(r) {
  switch (r.event) {
    case "skill_failure": case "skill_failed":
      return `${r.kind || "failure"}: ${r.reason || ""}`;
    case "request_end":
      return r.outcome === "success" ? "" : `${r.outcome}${r.reason ? ": " + r.reason : ""}`;
    case "request_dropped": case "halt": case "halt_abandoned": case "stop":
      return r.detail || r.reason || r.event;
    case "recovery_attempt": case "recovery_give_up": case "recovery_failed":
      return r.reason || r.last_failure || r.event;
    case "timeout":
      return `timed out after ${r.seconds} s`;
    case "operator_prompt_closed":
      return ["timeout", "failed", "declined"].includes(r.reason) ? r.reason : "";
    case "base_status":
      return r.status === "goal_fail" ? r.reason || "goal failed" : "";
    case "arm_status":
      return r.status === "fail" ? r.reason || "arm failed" : "";
    case "report":
      return r.level === "error" || r.level === "warning" ? r.message || "" : "";
    case "run_end":
      return r.outcome === "ok" || r.outcome === "stopped" ? "" : r.outcome;
    default:
      return r.error ? String(r.error) : "";
  }
}

export class LogView {
  constructor(box, filter, failuresOnly, follow, count) {
    this.box = box;
    this.filter = filter;
    this.failuresOnly = failuresOnly;
    this.follow = follow;
    this.count = count;
    this.records = [];
    this.lastSeq = -1;
    this.pending = false;
    for (const input of [filter, failuresOnly]) input.addEventListener("input", () => this.render());
  }

  clear() {
    this.records = [];
    this.lastSeq = -1;
    this.render();
  }

  add(record) {
    if (typeof record.seq === "number") {
      if (record.seq <= this.lastSeq) return;  // already shown (the tail and the stream overlap)
      this.lastSeq = record.seq;
    }
    this.records.push(record);
    if (this.records.length > KEEP) this.records.splice(0, this.records.length - KEEP);
    if (!this.pending) {  // redrawn at most 5 times a second: a busy run writes hundreds of records a second
      this.pending = true;
      setTimeout(() => { this.pending = false; this.render(); }, RENDER_EVERY);
    }
  }

  row(r) {
    const why = failureOf(r);
    const fields = Object.entries(r).filter(([k]) => !QUIET.has(k))
      .map(([k, v]) => `${k}=${fmtValue(v)}`).join("  ");
    const node = typeof r.node === "string" ? r.node.split("/").slice(-2).join("/") : "";
    return el("div", {class: why ? "entry fail" : `entry ev-${r.event}`, title: r.node || ""},
      el("span", {class: "t"}, typeof r.t === "number" ? r.t.toFixed(2) : ""),
      el("span", {class: "ev"}, r.event),
      node ? el("span", {class: "node"}, node) : "",
      why ? el("span", {class: "why"}, why) : "",
      el("span", {class: "fields"}, fields));
  }

  render() {
    const text = this.filter.value.trim().toLowerCase();
    const onlyFailures = this.failuresOnly.checked;
    const shown = [];
    for (let i = this.records.length - 1; i >= 0 && shown.length < SHOW; i--) {
      const r = this.records[i];
      if (onlyFailures && !failureOf(r)) continue;
      if (text && !JSON.stringify(r).toLowerCase().includes(text)) continue;
      shown.push(r);
    }
    shown.reverse();
    this.box.replaceChildren(...shown.map((r) => this.row(r)));
    this.count.textContent = `${shown.length} of ${this.records.length}`;
    if (this.follow.checked) this.box.scrollTop = this.box.scrollHeight;
  }
}
