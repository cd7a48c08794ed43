// The live tree: collapsible, statuses coloured, the running path highlighted, the
// branches of recovery (and if) nodes labelled, a node's blackboard values on click.

import {el, fmtValue} from "./util.js";

const KIND_SYMBOL = {
  "sequence": "→", "reactive sequence": "⇒", "fallback": "?", "reactive fallback": "⁇",
  "parallel": "⇉", "recovery": "↻", "if": "◇", "decorator": "◆", "leaf": "•",
};

export class TreeView {
  constructor(root, nodeBox, table, requestLabel, pathLabel) {
    this.root = root;            // <ul> of the tree
    this.nodeBox = nodeBox;      // the selected node's details
    this.table = table;          // all blackboard keys
    this.requestLabel = requestLabel;
    this.pathLabel = pathLabel;
    this.info = new Map();       // path -> {kind, branch, detail, reads, writes} (GET /api/mission)
    this.items = new Map();      // path -> {li, row, pill}
    this.status = new Map();     // path -> status
    this.shape = "";             // the node paths the DOM was built for
    this.collapsed = new Set();
    this.selected = "";
    this.blackboard = {};
    this.snap = null;            // the last tree message
    this.tip = "";               // the deepest running node, kept in view
    this.halted = new Set();     // nodes halted in this request (see nodeEvent)
  }

  // The mission's nodes (kind, branch labels, detail, keys), shown with the last tree
  // message when it is this mission's, else with every node INVALID (no request yet).
  setMission(mission) {
    this.info = new Map(mission.nodes.map((n) => [n.path, n]));
    const mine = this.snap && this.snap.nodes.every((n) => this.info.has(n.path));
    const skeleton = {request: null, t: 0, changed: [], nodes: mission.nodes.map((n) => ({
      path: n.path, name: n.name, status: "INVALID",
      parent: n.path.includes("/") ? n.path.slice(0, n.path.lastIndexOf("/")) : null}))};
    this.shape = "";
    this.update(mine ? this.snap : skeleton);
  }

  // A `tree` message: rebuild when the set of nodes changed, else restyle.
  update(snap) {
    const shape = snap.nodes.map((n) => n.path).join("\n");
    this.snap = snap;
    if (shape !== this.shape) this.build(snap.nodes, shape);
    for (const n of snap.nodes) this.status.set(n.path, n.status);
    this.requestLabel.textContent = snap.request == null ? "(no request yet)" : `request ${snap.request}`;
    this.restyle();
    this.showSelected();
  }

  build(nodes, shape) {
    this.shape = shape;
    this.items.clear();
    this.root.replaceChildren();
    for (const n of nodes) {
      const info = this.info.get(n.path) || {};
      const caret = el("button", {class: "caret", type: "button", "aria-label": "collapse"}, "▾");
      const pill = el("span", {class: "pill"}, "");
      const row = el("div", {class: "row", role: "treeitem", tabindex: "0", title: n.path},
        caret,
        info.branch ? el("span", {class: `branch branch-${info.branch}`}, `${info.branch}:`) : "",
        el("span", {class: "kind", title: info.kind || ""}, KIND_SYMBOL[info.kind] || "•"),
        el("span", {class: "name"}, n.name),
        info.detail ? el("span", {class: "detail"}, info.detail) : "",
        pill);
      const li = el("li", {class: "node", "data-path": n.path}, row);
      this.root.append(li);  // moved under its parent below
      this.items.set(n.path, {li, row, pill, caret});
      row.addEventListener("click", (ev) => {
        if (ev.target === caret) return;
        this.select(n.path);
      });
      row.addEventListener("keydown", (ev) => {
        if (ev.key === "Enter" || ev.key === " ") { ev.preventDefault(); this.select(n.path); }
      });
      caret.addEventListener("click", () => this.toggle(n.path));
    }
    // children lists, made after every node exists (pre-order: parents come first)
    for (const n of nodes) {
      if (n.parent === null || !this.items.has(n.parent)) continue;
      const parent = this.items.get(n.parent);
      let ul = parent.li.querySelector(":scope > ul");
      if (!ul) {
        ul = el("ul", {role: "group"});
        parent.li.append(ul);
      }
      ul.append(this.items.get(n.path).li);
    }
    for (const [path, item] of this.items) {
      const leaf = !item.li.querySelector(":scope > ul");
      item.caret.classList.toggle("none", leaf);
      item.li.classList.toggle("collapsed", this.collapsed.has(path) && !leaf);
    }
  }

  restyle() {
    let tip = "";
    for (const [path, item] of this.items) {
      const s = this.status.get(path) || "INVALID";
      const halted = this.halted.has(path);
      item.li.dataset.status = s;
      item.li.classList.toggle("halted", halted);
      item.pill.textContent = halted ? "halted" : s === "INVALID" ? "" : s.toLowerCase();
      if (s === "RUNNING") tip = path;
    }
    for (const [path, item] of this.items) {
      item.row.classList.toggle("tip", path === tip);
      item.row.classList.toggle("selected", path === this.selected);
    }
    if (tip && tip !== this.tip) this.reveal(this.items.get(tip).row);
    this.tip = tip;
  }

  // Scroll the tree (not the page) so that a row is in view: the running tip is followed.
  reveal(row) {
    const box = this.root, top = row.offsetTop;  // the tree list is the rows' offset parent
    if (top < box.scrollTop || top + row.offsetHeight > box.scrollTop + box.clientHeight) {
      box.scrollTop = top - box.clientHeight / 3;  // a third down: what runs next is in view too
    }
  }

  // From the event log (live, and the tail after a reload): a node that went from
  // RUNNING to INVALID was halted; marked until it runs again or the next request.
  nodeEvent(rec) {
    if (rec.event === "request_start") this.halted.clear();
    else if (rec.event !== "node_status") return;
    else if (rec.old === "RUNNING" && rec.new === "INVALID") this.halted.add(rec.path);
    else this.halted.delete(rec.path);
    this.restyle();
  }

  toggle(path) {
    const item = this.items.get(path);
    if (!item) return;
    if (this.collapsed.has(path)) this.collapsed.delete(path); else this.collapsed.add(path);
    item.li.classList.toggle("collapsed", this.collapsed.has(path));
  }

  expandAll() {
    this.collapsed.clear();
    for (const item of this.items.values()) item.li.classList.remove("collapsed");
  }

  // Collapse every subtree where nothing runs or ran (only what happened stays open).
  collapseIdle() {
    for (const [path, item] of this.items) {
      const hasChildren = !!item.li.querySelector(":scope > ul");
      const idle = (this.status.get(path) || "INVALID") === "INVALID";
      if (hasChildren && idle) this.collapsed.add(path); else this.collapsed.delete(path);
      item.li.classList.toggle("collapsed", this.collapsed.has(path));
    }
  }

  select(path) {
    this.selected = path;
    this.restyle();
    this.showSelected();
  }

  setBlackboard(values) {
    this.blackboard = values || {};
    this.table.replaceChildren(...Object.entries(this.blackboard).map(([k, v]) =>
      el("tr", {}, el("th", {}, k), el("td", {}, fmtValue(v)))));
    this.showSelected();
  }

  showSelected() {
    const path = this.selected;
    this.pathLabel.textContent = path;
    if (!path) return;
    const info = this.info.get(path) || {reads: [], writes: []};
    const status = this.status.get(path) || "INVALID";
    const keys = (names, what) => names.length === 0 ? [] : [
      el("h4", {}, what),
      el("table", {class: "kv"}, ...names.map((k) => el("tr", {},
        el("th", {}, k),
        el("td", {}, k in this.blackboard ? fmtValue(this.blackboard[k]) : el("span", {class: "muted"}, "(not set)"))))),
    ];
    this.nodeBox.replaceChildren(
      el("p", {}, el("span", {class: `pill status-${status}`}, status.toLowerCase()), " ",
        el("b", {}, info.kind || "node"), info.branch ? ` (${info.branch} branch)` : "",
        info.detail ? el("span", {class: "mono"}, "  " + info.detail) : ""),
      ...keys(info.reads || [], "reads"),
      ...keys(info.writes || [], "writes"),
      ...(info.reads && info.reads.length + info.writes.length ? [] :
        [el("p", {class: "muted"}, "This node reads and writes no blackboard key.")]),
    );
  }
}
