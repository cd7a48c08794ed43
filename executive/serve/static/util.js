// Small DOM and formatting helpers shared by the console's views.

// el("div", {class: "x", title: "y"}, child, "text", ...): a new element; strings become
// text nodes (never HTML), falsy children are skipped.
export function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    node.setAttribute(k, v === true ? "" : String(v));
  }
  for (const c of children) {
    if (c === undefined || c === null || c === false || c === "") continue;
    node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return node;
}

// A blackboard or event value as short text.
export function fmtValue(v) {
  if (typeof v === "number") return Number.isInteger(v) ? String(v) : String(Math.round(v * 1e4) / 1e4);
  if (typeof v === "string") return v === "" ? '""' : v;
  return JSON.stringify(v, (k, x) => (typeof x === "number" && !Number.isInteger(x) ? Math.round(x * 1e4) / 1e4 : x));
}

// Clock seconds as "12.35 s".
export function fmtTime(t) {
  return typeof t === "number" ? `${t.toFixed(2)} s` : "";
}
