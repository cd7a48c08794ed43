// The operator console of `mmexec serve`: wires the API and the live stream to the views.
// Shapes of every call and message: docs/console.md.

import {api, onUnauthorised, setToken, Stream, takeTokenFromUrl, token} from "./api.js";
import {CameraView, PromptView} from "./camera.js";
import {LogView} from "./log.js";
import {MapView} from "./mapview.js";
import {RequestForm, RequestList} from "./requests.js";
import {TreeView} from "./tree.js";

takeTokenFromUrl();
const $ = (id) => document.getElementById(id);

const tree = new TreeView($("tree"), $("node-info"), $("bb-table"), $("tree-request"), $("node-path"));
const map = new MapView($("map"), $("pose"));
const camera = new CameraView($("camera"), $("camera-info"));
const prompts = new PromptView($("prompt-card"), $("prompts"));
const log = new LogView($("log"), $("log-filter"), $("log-failures"), $("log-follow"), $("log-count"));
const list = new RequestList($("queue"), $("finished"), () => refreshRequests());
const form = new RequestForm($("request-form"), $("request-fields"), $("request-error"), $("mission-doc"),
                             () => refreshRequests());

let missionSha = "";
let runLog = null;       // the event log of the run shown (another one: the service restarted)
let requestsSig = "";
let tail = null;         // stream events held while the log's tail loads

// ------------------------------------------------------------------ header and banner

function banner(text, kind) {
  const b = $("banner");
  b.hidden = !text;
  b.textContent = text || "";
  b.className = `banner ${kind || ""}`;
}

function showStatus(st) {
  if (!st) return;
  $("mission-name").textContent = st.mission || "";
  $("backend").textContent = st.backend ? `backend ${st.backend}` : "";
  const state = $("state");
  state.textContent = st.state;
  state.className = `badge state-${st.state}`;
  $("clock").textContent = typeof st.t === "number" ? `t ${st.t.toFixed(2)} s` : "";
  const c = st.counts || {};
  $("counts").textContent = `${c.accepted || 0} accepted · ${c.succeeded || 0} ok · ${c.failed || 0} failed · ${c.dropped || 0} dropped`;
  const pause = $("pause");
  pause.textContent = st.paused ? "Resume" : "Pause";
  pause.classList.toggle("armed", !!st.paused);
  const ending = st.state === "stopping" || st.state === "stopped";
  for (const id of ["pause", "stop", "shutdown", "submit"]) $(id).disabled = ending;
  if (st.state === "stopped") banner("The service has stopped. The console reconnects when it runs again.", "warn");
  else if (st.paused && st.state !== "running") banner("Paused: no new request starts until Resume.", "info");
  else if ($("banner").classList.contains("info") || $("banner").classList.contains("warn")) banner("");
  prompts.tick(st.t);
  map.setRobot(st.robot);
  if (st.log && st.log !== runLog) newRun(st.log);
  const cur = st.current;
  const sig = JSON.stringify([cur && [cur.id, cur.state, cur.reason], st.queued, st.counts]);
  if (sig !== requestsSig) {
    requestsSig = sig;
    refreshRequests();
  }
}

let requestsCall = 0;
async function refreshRequests() {
  const mine = ++requestsCall;
  const r = await api("GET", "/api/requests");
  if (r.ok && mine === requestsCall) list.update(r.data);  // an older answer arriving late is stale
}

async function refreshMission() {
  const r = await api("GET", "/api/mission");
  if (!r.ok || r.data.sha256 === missionSha) return;
  missionSha = r.data.sha256;
  document.title = `mmexec · ${r.data.name}`;
  tree.setMission(r.data);
  form.setMission(r.data);
}

// Another run of the service (first connection, or it restarted): its log's tail.
async function newRun(path) {
  runLog = path;
  tail = [];
  log.clear();
  tree.nodeEvent({event: "request_start"});  // no node of another run is halted
  map.reset();
  camera.reset();
  const r = await api("GET", "/api/events?limit=500");
  const held = tail;
  tail = null;
  for (const rec of r.ok ? r.data : []) onEvent(rec);
  for (const rec of held) onEvent(rec);
}

// ------------------------------------------------------------------ the stream

function onEvent(rec) {
  if (tail) {
    tail.push(rec);
    return;
  }
  log.add(rec);
  tree.nodeEvent(rec);
  if (rec.event === "base_status") {
    if (rec.status === "to_goal" && Array.isArray(rec.goal)) {
      map.setGoal({x: rec.goal[0], y: rec.goal[1], theta: rec.goal[2] || 0, label: rec.label || ""});
    } else if (rec.status === "goal_ok" || rec.status === "goal_fail") {
      map.setGoal(null);
    }
  } else if (rec.event === "request_end" || rec.event === "request_start") {
    map.setGoal(null);
  }
}

const handlers = {
  hello(data) {
    showStatus(data.status);
    prompts.reset(data.prompts);
    refreshMission();
    refreshRequests();
  },
  status: showStatus,
  tree: (data) => tree.update(data),
  event: onEvent,
  pose: (data) => map.setPose(data),
  path: (data) => map.setPath(data.points),
  map: (data) => map.setMap(data),
  scan: (data) => map.setScan(data),
  markers: (data) => map.setMarkers(data.markers),
  people: (data) => map.setPeople(data.people),
  camera: (data) => camera.setFrame(data),
  prompt: (data) => prompts.message(data),
  blackboard: (data) => tree.setBlackboard(data.values),
  error: (data) => banner(data.error, "error"),
};

const stream = new Stream((msg) => {
  const fn = handlers[msg.type];
  if (fn) fn(msg.data);
}, (state, detail) => {
  const conn = $("conn");
  conn.textContent = state === "up" ? "live" : "offline";
  conn.className = `conn ${state}`;
  if (state === "up") {
    if ($("banner").classList.contains("down")) banner("");
  } else if (!needToken) {
    banner(`The service cannot be reached: ${detail}.`, "down");
  }
});

// ------------------------------------------------------------------ controls

$("pause").addEventListener("click", async () => {
  const paused = $("pause").textContent === "Resume";
  const r = await api("POST", paused ? "/api/resume" : "/api/pause");
  if (r.ok) showStatus(r.data); else banner(r.data.error, "error");
});

// STOP: no new request starts (pause), and the running one halts: its skills are
// cancelled, the base brakes and the arm holds. Resume serves the queue again.
$("stop").addEventListener("click", async () => {
  const paused = await api("POST", "/api/pause");
  const halted = await api("POST", "/api/halt");
  if (!paused.ok) banner(paused.data.error, "error");
  else if (halted.ok) banner(`STOP: request ${halted.data.id} is halting; the queue is paused (Resume to go on).`, "warn");
  else banner("STOP: nothing was running; the queue is paused (Resume to go on).", "warn");
  refreshRequests();
});

let armed = null;
$("shutdown").addEventListener("click", async () => {
  const b = $("shutdown");
  if (!armed) {
    b.textContent = "Confirm shut down";
    b.classList.add("armed");
    armed = setTimeout(() => { armed = null; b.textContent = "Shut down"; b.classList.remove("armed"); }, 4000);
    return;
  }
  clearTimeout(armed);
  armed = null;
  b.textContent = "Shut down";
  b.classList.remove("armed");
  const r = await api("POST", "/api/stop");
  if (!r.ok) banner(r.data.error, "error");
});

$("tree-expand").addEventListener("click", () => tree.expandAll());
$("tree-collapse").addEventListener("click", () => tree.collapseIdle());

// A call or the stream refused for want of the token: the form says so (not "cannot be reached").
let needToken = false;
onUnauthorised(() => {
  needToken = true;
  $("token-why").textContent = token() ? "The service refused this token; enter its token" :
    "This service needs its token";
  $("token-input").value = "";
  $("token-form").hidden = false;
  $("token-input").focus();
  if ($("banner").classList.contains("down")) banner("");
});
$("token-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  setToken($("token-input").value);
  needToken = false;
  $("token-form").hidden = true;
  stream.restart();
});

stream.connect();
